"""The tour check: the camera poses a route drives through, and how often each object is in view.

:func:`route_poses` samples the poses of a route, :func:`tour_view_counts` counts, per object, the
poses that have it in view (:func:`app.ocslam.visibility.in_view_matrix`): the fast geometric test
that a world's ``tour`` brings every object into view. :func:`plan_look_tour` plans such a tour.

Example:
    >>> counts = tour_view_counts(load_world("assets/worlds/apartment.yaml"))   # (N,) per object
    >>> bool((counts >= 5).all())
    True
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray
from shapely.geometry import Polygon
from shapely.ops import unary_union

from app.ocslam.visibility import in_view_matrix
from app.world.models.catalogue import get_model
from app.world.planner import Planner
from app.world.types import ROBOT_RADIUS_M, ROUTE_MARGIN_M

__all__ = ["route_poses", "polyline_poses", "occluders_for", "tour_view_counts", "plan_look_tour", "CAMERA_HEIGHT_M"]

#: the Burger's camera height (camera_optical_frame above base_footprint, URDF)
CAMERA_HEIGHT_M = 0.19
#: default horizontal field of view (camera.hfov_rad)
HFOV_RAD = 1.04


# ----------------------------------------------------------------------------------------------
# Tour check
# ----------------------------------------------------------------------------------------------


def polyline_poses(pts: Sequence[tuple[float, float]], yaw0: float, step_m: float = 0.1, turn_step_rad: float = 0.15,
                   ) -> tuple[NDArray[np.float64], float]:
    """Poses ``[x, y, yaw]`` along a polyline driven from ``pts[0]`` with heading ``yaw0`` (see
    :func:`route_poses`) and the final heading."""
    out: list[tuple[float, float, float]] = []
    yaw = float(yaw0)
    for (x0, y0), (x1, y1) in zip(pts[:-1], pts[1:]):
        L = math.hypot(x1 - x0, y1 - y0)
        if L < 1e-6:
            continue
        h = math.atan2(y1 - y0, x1 - x0)
        d = (h - yaw + math.pi) % (2 * math.pi) - math.pi
        for k in range(int(abs(d) / turn_step_rad) + 1):
            out.append((x0, y0, yaw + math.copysign(k * turn_step_rad, d)))
        yaw = h
        for t in np.arange(0.0, L, step_m):
            out.append((x0 + t / L * (x1 - x0), y0 + t / L * (y1 - y0), h))
    out.append((pts[-1][0], pts[-1][1], yaw))
    return np.asarray(out, dtype=np.float64).reshape(-1, 3), yaw


def route_poses(world: Any, route: str = "tour", step_m: float = 0.1, turn_step_rad: float = 0.15) -> NDArray[np.float64]:
    """``(P, 3)`` poses ``[x, y, yaw]`` (world frame) the robot passes driving ``route`` from ``start``:
    every ``step_m`` along each segment facing along it, and every ``turn_step_rad`` while turning in
    place at a waypoint (the start pose's heading first)."""
    pts = [(world.start.x, world.start.y)] + [tuple(p) for p in world.route(route)]
    return polyline_poses(pts, float(world.start.yaw), step_m, turn_step_rad)[0]


def occluders_for(world: Any, camera_z: float = CAMERA_HEIGHT_M) -> list[Any]:
    """Per object, the geometry that can hide it from the camera: the walls' solid part at the
    camera's height, and every obstacle or other object that is not legged (legs are see-through) and
    at least 0.7 × as tall as it. Shrunk by 2 cm so touching neighbours do not hide each other."""
    walls = unary_union([w.solid_polygon(z=camera_z) for w in world.walls])
    solids: list[tuple[Any, float, bool, int]] = []  # (polygon, top, legged, object index or -1)
    for o in world.obstacles:
        legged = o.shape == "model" and get_model(o.model).legged
        z0, z1 = o.z_range()
        if z0 <= camera_z:
            solids.append((Polygon(o.footprint()), z1, legged, -1))
    for i, o in enumerate(world.objects):
        solids.append((Polygon(o.footprint()), o.z_range()[1], o.legged, i))
    out = []
    for i, o in enumerate(world.objects):
        top = o.z_range()[1]
        parts = [walls] + [p for p, z1, legged, k in solids if k != i and not legged and z1 >= 0.7 * top]
        out.append(unary_union(parts).buffer(-0.02))
    return out


def tour_view_counts(
    world: Any, route: str = "tour", hfov_rad: float = HFOV_RAD, max_range_m: float = 3.0, min_range_m: float = 0.3,
    occluders: list[Any] | None = None,
) -> NDArray[np.int64]:
    """``(N,)`` number of sampled route poses (:func:`route_poses`, 0.1 m apart) from which each object
    is in view, within 3 m by default (inside the LIDAR's 3.5 m, close enough for the detector)."""
    poses = route_poses(world, route)
    fps = [o.footprint() for o in world.objects]
    occ = occluders if occluders is not None else occluders_for(world)
    m = in_view_matrix(poses, fps, occ, hfov_rad, max_range_m=max_range_m, min_range_m=min_range_m)
    return m.sum(axis=0)


def tour_planner(world: Any, res: float = 0.05) -> Planner:
    """The :class:`Planner` that :func:`plan_look_tour` plans its legs on: robot radius + route margin + 2 cm
    from everything, 0.35 m preferred, ``res`` m cells."""
    return Planner(world, ROBOT_RADIUS_M + ROUTE_MARGIN_M + 0.02, preferred=0.35, res=res)


def plan_look_tour(
    world: Any,
    base: Sequence[tuple[float, float]] | None = None,
    *,
    min_views: int = 10,
    max_range_m: float = 3.0,
    hfov_rad: float = HFOV_RAD,
    distances: Sequence[float] = (1.3, 1.7, 1.0, 2.2, 2.7),
    approach_m: float = 0.6,
    max_legs: int = 60,
    strict: bool = True,
    res: float = 0.05,
    planner: Planner | None = None,
) -> list[tuple[float, float]] | None:
    """A ``tour`` that brings every object into view: from ``start``, repeatedly drive to the nearest
    object not yet seen from ``min_views`` route poses, ending with a straight ``approach_m`` run
    towards it from ``distances`` away (so the camera faces it), then return to ``start``. Legs are
    planned on the rooms family's grid (robot radius + margin + 2 cm from everything, shortened by
    string pulling). ``base`` (goals from ``start``, e.g. a hand-written loop; legs between them are
    planned) is driven first.
    ``None`` when a leg cannot be planned or (``strict``) some object stays out of view. ``res``: the
    planning grid's cell size (m); ``planner``: the caller's :class:`Planner` of this world with these settings
    (``tour_planner(world, res)``), instead of a new one (its distance grid is most of its cost)."""
    planner = planner if planner is not None else tour_planner(world, res)
    occ = occluders_for(world)
    fps = [o.footprint() for o in world.objects]
    start = (float(world.start.x), float(world.start.y))
    route: list[tuple[float, float]] = []

    seen = np.zeros(len(fps), dtype=np.int64)
    state = {"n": 0, "yaw": float(world.start.yaw)}  # route points already counted, heading there

    def counts() -> NDArray[np.int64]:
        allpts = [start] + route
        pts = allpts[max(0, state["n"] - 1):]
        if state["n"] == 0 or len(pts) >= 2:
            poses, state["yaw"] = polyline_poses(pts, state["yaw"])
            if state["n"]:
                poses = poses[1:]  # the last pose of the previous call, counted then
            if len(poses):
                seen[:] += in_view_matrix(poses, fps, occ, hfov_rad, max_range_m=max_range_m, min_range_m=0.3).sum(axis=0)
            state["n"] = len(allpts)
        return seen

    def plan(a: tuple[float, float], b: tuple[float, float]) -> list[tuple[float, float]] | None:
        if free(a) and free(b) and planner.clear(a, b):
            return [a, b]
        return planner.plan(a, b)

    def free(p: tuple[float, float]) -> bool:
        r, c = planner.cell(*p)
        return 0 <= r < planner.H and 0 <= c < planner.W and bool(planner.free[r, c]) and planner.dist[r, c] >= planner.clearance + 0.03

    def append(path: list[tuple[float, float]]) -> None:
        for pt in path[1:]:
            q = (round(pt[0], 3), round(pt[1], 3))
            if not route or q != route[-1]:
                route.append(q)

    for g in base or []:  # the base goals, joined by planned legs
        leg = plan(route[-1] if route else start, (float(g[0]), float(g[1])))
        if leg is None:
            return None
        append(leg)
    failed: set[int] = set()
    looks: dict[int, list[tuple[float, tuple[float, float], tuple[float, float]]]] = {}  # object → its approaches

    def approaches(j: int) -> list[tuple[float, tuple[float, float], tuple[float, float]]]:
        """``(d, p, v)``: drivable straight approaches ``p → v`` to object ``j`` from which the camera sees it
        (they depend on the object and the grid only: worked out once)."""
        if j in looks:
            return looks[j]
        o = world.objects[j]
        reach = []  # (d, p, v, yaw): drivable approaches, then the ones from which the camera sees it
        for d in distances:
            for a in np.linspace(-math.pi, math.pi, 32, endpoint=False):
                u = np.array([math.cos(a), math.sin(a)])
                v = (float(o.x + d * u[0]), float(o.y + d * u[1]))
                p = (float(o.x + (d + approach_m) * u[0]), float(o.y + (d + approach_m) * u[1]))
                if free(v) and free(p) and planner.clear(p, v):
                    reach.append((d, p, v, math.atan2(-u[1], -u[0])))
        sees = in_view_matrix(np.array([[r[2][0], r[2][1], r[3]] for r in reach]).reshape(-1, 3), [fps[j]], [occ[j]],
                              hfov_rad * 0.8, max_range_m=max_range_m)[:, 0]
        looks[j] = [(d, p, v) for (d, p, v, _), ok in zip(reach, sees) if ok]
        return looks[j]

    for _ in range(max_legs):
        seen = counts()
        todo = [j for j in range(len(fps)) if seen[j] < min_views and j not in failed]
        if not todo:
            break
        cur = route[-1] if route else start
        todo.sort(key=lambda j: math.hypot(world.objects[j].x - cur[0], world.objects[j].y - cur[1]))
        done_one = False
        for j in todo:
            cands = [(math.hypot(p[0] - cur[0], p[1] - cur[1]) + 0.5 * abs(d - 1.5), p, v) for d, p, v in approaches(j)]
            cands.sort(key=lambda c: c[0])
            for _, p, v in cands[:6]:
                leg = plan(cur, p)
                if leg is None or not planner.clear(leg[-1], v):
                    continue
                append(leg)
                append([route[-1], v])
                done_one = True
                break
            if done_one:
                break
            failed.add(j)
        if not done_one and not todo:
            break
    if route and math.hypot(route[-1][0] - start[0], route[-1][1] - start[1]) > 0.05:
        back = plan(route[-1], start)
        if back is None:
            return None
        append(back)
    seen = counts()
    return route if (seen >= min_views).all() or not strict else None
