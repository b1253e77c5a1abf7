"""2D graph SLAM: log-odds grid, correlative + continuous scan matching, keyframe pose graph, loops.

Public API: :class:`Slam` (the online facade), :class:`PoseGraph`, the CARMEN reader and the metrics.
See ``docs/slam.md``.
"""

from app.ocslam.slam.carmen import CarmenError, CarmenLog, beam_layout, read_carmen
from app.ocslam.slam.graph import PoseGraph
from app.ocslam.slam.mapper import Slam
from app.ocslam.slam.metrics import ate_rmse, map_agreement, read_relations, relation_errors

__all__ = [
    "Slam",
    "PoseGraph",
    "CarmenError",
    "CarmenLog",
    "beam_layout",
    "read_carmen",
    "ate_rmse",
    "map_agreement",
    "read_relations",
    "relation_errors",
]
