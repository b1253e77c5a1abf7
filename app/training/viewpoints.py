"""Camera viewpoints for the dataset renders (``ocslam dataset``, see :mod:`app.training.dataset`).

:func:`sample_viewpoint` draws a free robot pose ``Pose2`` in the world frame: looking at an object from
a random side and distance from its footprint's edge (with a line of sight to it), along one of the
world's routes, or anywhere free; with ``close_views`` > 0 that share of the draws is a *close view*: the camera
within an object's footprint (under a table's top, between its legs: the robot drives there) or at most 0.3 m from
its edge, looking any way from inside and towards it from outside, so the object fills or overflows the frame.
"""

from __future__ import annotations

import math

import numpy as np

from app.training.randomization import Randomizer

__all__ = ["sample_viewpoint"]


def _edge_distance(o, angle: float) -> float:
    """Distance from an object's centre to its footprint's edge in direction ``angle``."""
    from shapely.geometry import LineString, Polygon

    far = LineString([(o.x, o.y), (o.x + 20 * math.cos(angle), o.y + 20 * math.sin(angle))])
    hit = Polygon(o.footprint()).exterior.intersection(far)
    if hit.is_empty:
        return 0.0
    pts = np.asarray([g.coords[0] for g in getattr(hit, "geoms", [hit])])
    return float(np.max(np.hypot(pts[:, 0] - o.x, pts[:, 1] - o.y)))


def _line_of_sight(sim, xy: tuple[float, float], oid: int) -> bool:
    """True if a ray from camera height at ``xy`` to the object's mid-height centre first meets the object."""
    import pybullet as p

    o = sim.world.objects[oid]
    z0, z1 = o.z_range()
    hit = p.rayTest([xy[0], xy[1], 0.2], [o.x, o.y, max(0.03, min((z0 + z1) / 2, 0.6))], physicsClientId=sim.client)[0]
    return hit[0] < 0 or hit[0] in sim.object_body_ids.get(oid, ())


def _close_view(o, rng: np.random.Generator) -> tuple[float, float, float]:
    """A pose ``(x, y, yaw)`` inside ``o``'s footprint or at most 0.3 m outside its edge."""
    a = rng.uniform(-math.pi, math.pi)
    edge = _edge_distance(o, a)
    d = edge * float(rng.uniform(0.0, 1.0)) if rng.random() < 0.5 else edge + float(rng.uniform(0.05, 0.3))
    x, y = o.x + d * math.cos(a), o.y + d * math.sin(a)
    inside = d < edge
    yaw = rng.uniform(-math.pi, math.pi) if inside else math.atan2(o.y - y, o.x - x) + rng.uniform(-0.8, 0.8)
    return x, y, float(yaw)


def sample_viewpoint(sim, rz: Randomizer, rng: np.random.Generator, tries: int = 60, close_views: float = 0.0):
    """A free robot pose ``Pose2`` (looking at an object, close to or under one, along a route, or anywhere) or
    None. ``close_views`` is the share of draws that are close views (0 draws no extra random number, so a
    dataset's recipe without them renders the same images as before the option)."""
    from app.ocslam.se2 import Pose2

    world = sim.world
    xmin, ymin, xmax, ymax = rz.bounds
    routes = [np.asarray(r, dtype=np.float64).reshape(-1, 2) for r in world.routes.values() if len(r) >= 2]
    for _ in range(tries):
        if close_views > 0.0 and world.objects and rng.random() < close_views:
            x, y, yaw = _close_view(world.objects[int(rng.integers(len(world.objects)))], rng)
            if rz.free_for_camera(float(x), float(y)):
                return Pose2(float(x), float(y), float(yaw))
            continue
        mode = rng.random()
        if mode < 0.7 and world.objects:
            oid = int(rng.integers(len(world.objects)))
            o = world.objects[oid]
            a = rng.uniform(-math.pi, math.pi)
            # distance from the object's footprint edge (large objects are seen from further away)
            d = _edge_distance(o, a) + float(rng.uniform(0.25, 3.5) if rng.random() < 0.85 else rng.uniform(0.1, 0.5))
            x, y = o.x + d * math.cos(a), o.y + d * math.sin(a)
            yaw = math.atan2(o.y - y, o.x - x) + rng.uniform(-0.5, 0.5)
            if not _line_of_sight(sim, (x, y), oid):
                continue
        elif mode < 0.9 and routes:
            r = routes[int(rng.integers(len(routes)))]
            k = int(rng.integers(len(r) - 1))
            t = rng.random()
            x, y = r[k] + t * (r[k + 1] - r[k])
            seg = r[k + 1] - r[k]
            yaw = math.atan2(seg[1], seg[0]) + rng.normal(0.0, 0.5) + (math.pi if rng.random() < 0.2 else 0.0)
        else:
            x, y = rng.uniform(xmin, xmax), rng.uniform(ymin, ymax)
            yaw = rng.uniform(-math.pi, math.pi)
        if rz.free_for_camera(float(x), float(y)):
            return Pose2(float(x), float(y), float(yaw))
    return None
