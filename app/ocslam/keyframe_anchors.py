"""The SLAM keyframes the objects' evidence is anchored to (improved mode; docs/consciousness.md, "The SLAM frame").

Every piece of evidence (points, bisector rays, ground-plane centres) is tagged with the keyframe the robot
was attached to when it was seen. When SLAM moves a keyframe (a loop closure, a graph optimisation, or a
known keyframe given again with a new pose), the evidence tagged with it moves by the same rigid motion
``T_map_kf_new · T_map_kf_old⁻¹``. This module keeps the keyframes' last known poses and turns new poses
into those motions; applying them to the tracks is the node's.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from app.ocslam.evidence import NO_KEYFRAME
from app.ocslam.se2 import Pose2

#: A keyframe motion smaller than this (m, rad) in every component is no motion.
_EPS = 1e-9


def _moved(d: Pose2) -> bool:
    return abs(d.x) > _EPS or abs(d.y) > _EPS or abs(d.yaw) > _EPS


class KeyframeAnchors:
    """``poses``: the last known ``T_map_keyframe`` of every keyframe evidence was anchored to."""

    def __init__(self, poses: dict[int, Pose2] | None = None) -> None:
        self.poses: dict[int, Pose2] = dict(poses or {})

    def attach(self, keyframe: tuple[int, Pose2] | None) -> tuple[int, dict[int, Pose2]]:
        """The keyframe new evidence is anchored to (``NO_KEYFRAME`` for none or a non-finite pose) and, when
        it was known with another pose, its motion ``{k: T_new · T_old⁻¹}`` (a correction; else ``{}``)."""
        if keyframe is None:
            return NO_KEYFRAME, {}
        k, T_map_kf = int(keyframe[0]), keyframe[1]
        if not all(math.isfinite(v) for v in T_map_kf):
            return NO_KEYFRAME, {}
        old = self.poses.get(k)
        self.poses[k] = T_map_kf
        if old is not None:
            d = T_map_kf @ old.inverse()
            if _moved(d):
                return k, {k: d}
        return k, {}

    def correct(self, keyframe_pose: Callable[[int], Pose2]) -> dict[int, Pose2]:
        """New poses of every known keyframe from ``keyframe_pose(k)`` (unknown ones: ``KeyError`` or
        ``IndexError``; ``None`` or non-finite: kept as they were); returns the motions of those that moved."""
        deltas: dict[int, Pose2] = {}
        for k, old in list(self.poses.items()):
            try:
                new = keyframe_pose(k)
            except (KeyError, IndexError):
                continue
            if new is None or not all(math.isfinite(v) for v in new):
                continue
            d = new @ old.inverse()
            self.poses[k] = new
            if _moved(d):
                deltas[k] = d
        return deltas
