"""A replay's run directory: the same files as a headless run's (``app.session``), written as a unit.

``config.yaml``, ``summary.json``, ``map.yaml`` + ``map.pgm``, ``objects.json`` (vision_msgs/Detection3D
entries), ``trajectory_slam.tum`` and ``trajectory_odom.tum``. A replay has no simulator, so there is
no ``state.npz`` (a replayed map is not continued in the simulator) and no ``scene.viser``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from app.ros2.replay import ReplayCore


def _json_default(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def write_files(core: ReplayCore, d: Path, summary: dict[str, Any]) -> None:
    """Fill directory ``d`` with the replay's results."""
    from app.config import atomic_write_text
    from app.ocslam.mapio import save_map
    from app.session import object_to_detection3d, tum_lines

    d.mkdir(parents=True, exist_ok=True)
    core.cfg.save(d / "config.yaml")
    atomic_write_text(d / "summary.json", json.dumps(summary, indent=2, default=_json_default))
    if core.cfg.slam.enabled:
        grid = core.slam.occupancy_grid(budget=10**9)
        if grid.width and grid.height:
            save_map(grid, d / "map.yaml")
        stamps, traj = core.slam.trajectory()
        atomic_write_text(d / "trajectory_slam.tum", tum_lines(stamps, traj))
    thr = core.cfg.consciousness.presence_threshold
    dets = [object_to_detection3d(o, core.time, "map") for o in core.objects_in_map() if o.presence >= thr]
    atomic_write_text(d / "objects.json", json.dumps(
        {"frame_id": "map", "presence_threshold": thr, "stamp": core.time, "detections": dets}, indent=2,
        default=_json_default))
    log = core.state.odom_log
    if log:
        s = np.array([t for t, _ in log])
        o = np.array([p.as_array() for _, p in log])
        atomic_write_text(d / "trajectory_odom.tum", tum_lines(s, o))


def write_run_dir(core: ReplayCore, out: str | Path, summary: dict[str, Any]) -> Path:
    """Write ``out`` as a unit (:func:`app.session.write_run_dir` where available)."""
    try:
        from app.session import write_run_dir as write_unit
    except ImportError:
        write_unit = None
    if write_unit is None:
        out = Path(out)
        write_files(core, out, summary)
        return out
    return write_unit(out, lambda d: write_files(core, Path(d), summary))
