"""A world's ground truth as messages: the classified objects and the unclassified obstacles (walls
included), all in the world frame. For evaluation and overlays only: nothing in the loop reads it."""

from __future__ import annotations

import numpy as np

from app.ocslam.messages import GroundTruthObject, GroundTruthObstacle
from app.world.types import World

__all__ = ["ground_truth_objects", "ground_truth_obstacles"]


def ground_truth_objects(world: World) -> list[GroundTruthObject]:
    """Every classified object: id (= index in ``world.objects``, as in segmentations), class,
    pose, CCW footprint polygon and height range, in the world frame."""
    out = []
    for i, o in enumerate(world.objects):
        z0, z1 = o.z_range()
        out.append(
            GroundTruthObject(
                id=i,
                label=o.label,
                pose=o.pose,
                footprint=o.footprint(),
                z_min=z0,
                z_max=z1,
                legged=o.legged,
                name=world.object_name(i),
                frame_id="world",
            )
        )
    return out


def ground_truth_obstacles(world: World) -> list[GroundTruthObstacle]:
    """Walls (one entry per solid piece, openings cut out) and unclassified obstacles, world frame."""
    out = []
    for i, w in enumerate(world.walls):
        for _k, (s0, s1, z0, z1, _, _) in enumerate(w.boxes()):
            poly = np.asarray(w._span_polygon(s0, s1).exterior.coords)[:-1]
            out.append(GroundTruthObstacle(poly, z0, z1, kind="wall", name=f"walls[{i}]" + (f" {w.name}" if w.name else "")))
    for i, o in enumerate(world.obstacles):
        z0, z1 = o.z_range()
        out.append(GroundTruthObstacle(o.footprint(), z0, z1, kind="obstacle", name=o.name or f"obstacles[{i}]"))
    return out
