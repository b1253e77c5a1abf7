"""Layout families for ``world random`` and the geometric tour check of hand-written worlds.

``random_world(seed)`` in :mod:`app.worlds` builds today's *rooms* family (a rectangle split into
rooms). This module adds families that look like other places people live and work in, each
furnished with *groups* (a table with chairs pushed in around it, a sofa + armchair + low table, a row
of shelves, a person by a door) as well as single objects:

- ``corridor``: a corridor with doors at both ends and along it, offices off one or both sides;
- ``lshape``: an L-shaped flat (living room in one arm, kitchen/dining in the other, a bedroom);
- ``openplan``: one open space with kitchen, dining and living zones and a few partition stubs.

Every world validates (:func:`app.worlds.validate_world`), holds every class at least once and has a
``tour`` route planned on a grid inflated by the robot radius + margin (the same planner as the
rooms family). ``generate(family, seed)`` is deterministic.

The tour check (:func:`route_poses`, :func:`tour_view_counts`) samples the camera poses a route
drives through and counts, per object, the poses that have it in view (:func:`app.ocslam.evaluation.in_view_matrix`):
the fast geometric test that a world's ``tour`` brings every object into view.

Example:
    >>> w = generate("corridor", 99000)
    >>> counts = tour_view_counts(w)          # (N,) poses with each object in view
    >>> bool((counts >= 5).all())
    True
"""

from __future__ import annotations

import math
from typing import Any, Callable, Sequence

import numpy as np
from numpy.typing import NDArray
from shapely.geometry import Point, Polygon
from shapely.ops import unary_union

from app.ocslam.evaluation import in_view_matrix
from app.world_models import get_model

__all__ = [
    "FAMILIES",
    "generate",
    "route_poses",
    "occluders_for",
    "tour_view_counts",
    "CAMERA_HEIGHT_M",
]

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
) -> list[tuple[float, float]] | None:
    """A ``tour`` that brings every object into view: from ``start``, repeatedly drive to the nearest
    object not yet seen from ``min_views`` route poses, ending with a straight ``approach_m`` run
    towards it from ``distances`` away (so the camera faces it), then return to ``start``. Legs are
    planned on the rooms family's grid (robot radius + margin + 2 cm from everything, shortened by
    string pulling). ``base`` (goals from ``start``, e.g. a hand-written loop; legs between them are
    planned) is driven first.
    ``None`` when a leg cannot be planned or (``strict``) some object stays out of view. ``res``: the
    planning grid's cell size (m)."""
    from app.worlds import ROBOT_RADIUS_M, ROUTE_MARGIN_M, _Planner

    planner = _Planner(world, ROBOT_RADIUS_M + ROUTE_MARGIN_M + 0.02, preferred=0.35, res=res)
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
    for _ in range(max_legs):
        seen = counts()
        todo = [j for j in range(len(fps)) if seen[j] < min_views and j not in failed]
        if not todo:
            break
        cur = route[-1] if route else start
        todo.sort(key=lambda j: math.hypot(world.objects[j].x - cur[0], world.objects[j].y - cur[1]))
        done_one = False
        for j in todo:
            o = world.objects[j]
            cands = []
            for d in distances:
                for a in np.linspace(-math.pi, math.pi, 32, endpoint=False):
                    u = np.array([math.cos(a), math.sin(a)])
                    v = (float(o.x + d * u[0]), float(o.y + d * u[1]))
                    p = (float(o.x + (d + approach_m) * u[0]), float(o.y + (d + approach_m) * u[1]))
                    if not (free(v) and free(p) and planner.clear(p, v)):
                        continue
                    yaw = math.atan2(-u[1], -u[0])
                    if not in_view_matrix(np.array([[v[0], v[1], yaw]]), [fps[j]], [occ[j]], hfov_rad * 0.8, max_range_m=max_range_m)[0, 0]:
                        continue
                    cands.append((math.hypot(p[0] - cur[0], p[1] - cur[1]) + 0.5 * abs(d - 1.5), p, v))
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


# ----------------------------------------------------------------------------------------------
# Layout families
# ----------------------------------------------------------------------------------------------

T_OUT, T_IN, WALL_H = 0.3, 0.15, 2.4
#: free space kept between furniture groups (the robot's diameter + margins)
GROUP_GAP_M = 0.55

Item = tuple  # (label | None, model, x, y, yaw_rad[, scale]) in a group's frame (+x into the room)


def _group_dining(rng: np.random.Generator) -> list[Item]:
    """A table with chairs pushed in around it (and sometimes a ball between two chairs' legs);
    origin at the table's centre."""
    if rng.random() < 0.3:
        n = int(rng.integers(2, 5))
        items: list[Item] = [("table", "round_table", 0.0, 0.0, 0.0)]
        a0 = float(rng.uniform(0, 2 * math.pi))
        for k in range(n):
            a = a0 + 2 * math.pi * k / n
            items.append(("chair", "dining_chair", 0.72 * math.cos(a), 0.72 * math.sin(a), a + math.pi))
        return items
    items = [("table", "table", 0.0, 0.0, 0.0)]
    slots = [(-0.72, -0.45, 0.0), (-0.72, 0.45, 0.0), (0.72, -0.45, math.pi), (0.72, 0.45, math.pi),
             (0.0, 1.12, -math.pi / 2), (0.0, -1.12, math.pi / 2)]
    chosen = sorted(int(k) for k in rng.permutation(6)[: int(rng.integers(3, 7))])
    for k in chosen:
        x, y, yaw = slots[k]
        items.append(("chair", "dining_chair", x, y, yaw))
    if {0, 1} <= set(chosen) and rng.random() < 0.4:  # a ball between the legs of two chairs
        items.append(("ball", "play_ball", -0.72, 0.0, 0.0))
    return items


def _group_lounge(rng: np.random.Generator) -> list[Item]:
    """Sofa against the wall, an armchair (or a second sofa: an L) at its side and a low table."""
    side = 1.0 if rng.random() < 0.5 else -1.0
    sofa = "sofa3" if rng.random() < 0.3 else "sofa"
    half = 1.1 if sofa == "sofa3" else 0.9
    items: list[Item] = [("chair", sofa, 0.5, 0.0, 0.0)]
    if rng.random() < 0.4:  # two sofas in an L
        items.append(("chair", "sofa", 0.9, side * (half + 0.5 + 0.02), -side * math.pi / 2))  # its end against the wall
    else:
        items.append(("chair", "armchair", 1.65, side * (half + 0.55 + 0.1), -side * math.pi / 2))
    if rng.random() < 0.5:
        items.append((None, "box:0.5x0.9x0.4", 1.6, 0.0, 0.0))
    else:
        items.append(("table", "round_table", 1.75, 0.0, 0.0))
    return items


def _group_shelves(rng: np.random.Generator) -> list[Item]:
    """Two or three shelves side by side against a wall."""
    model = "bookshelf" if rng.random() < 0.6 else "low_shelf"
    w, d = (1.0, 0.4) if model == "bookshelf" else (1.2, 0.35)
    n = int(rng.integers(2, 4))
    return [("shelf", model, d / 2, (k - (n - 1) / 2) * w, 0.0) for k in range(n)]


def _group_desk(rng: np.random.Generator) -> list[Item]:
    """A desk (table) against the wall with its chair pushed in."""
    items: list[Item] = [("table", "table", 0.5, 0.0, 0.0), ("chair", "dining_chair", 1.22, float(rng.uniform(-0.4, 0.4)), math.pi)]
    if rng.random() < 0.5:
        items.append((None, "trash_bin", 0.16, 0.9 + 0.16, 0.0))
    return items


def _group_clutter_pair(rng: np.random.Generator) -> list[Item]:
    """A classified object against the wall with unclassified clutter touching it."""
    label, model, depth = [("extinguisher", "fire_extinguisher", 0.125), ("flowers", "potted_flowers", 0.1),
                           ("gnome", "gnome", 0.14), ("shelf", "low_shelf", 0.175)][int(rng.integers(4))]
    clutter, cr = [("trash_bin", 0.155), ("cardboard_box", 0.23), ("stool", 0.17)][int(rng.integers(3))]
    half = 0.6 if model == "low_shelf" else 0.13
    return [(label, model, depth, 0.0, 0.0), (None, clutter, cr, half + cr + 0.005, 0.0)]


_WALL_SINGLES = [("extinguisher", "fire_extinguisher", 0.125), ("flowers", "potted_flowers", 0.1), ("gnome", "gnome", 0.14),
                 ("dog", "dog", 0.14), ("chair", "armchair", 0.5), ("shelf", "low_shelf", 0.175)]
_FREE_SINGLES = [("ball", "soccer_ball"), ("ball", "play_ball"), ("duck", "rubber_duck"), ("dog", "dog"), ("person", "person"),
                 ("gnome", "gnome"), ("flowers", "potted_flowers")]


class _Builder:
    """Walls, zones and furniture of one generated world (world frame, radians)."""

    def __init__(self, rng: np.random.Generator, name: str, seed: int, description: str) -> None:
        from app.worlds import World, _FLOORS, _WALLS

        self.rng = rng
        self.world = World(name=name, description=description, seed=int(seed),
                           floor_color=_FLOORS[int(rng.integers(len(_FLOORS)))], wall_color=_WALLS[int(rng.integers(len(_WALLS)))])
        self.zones: list[tuple[str, tuple[float, float, float, float]]] = []
        self.placed: list[Any] = []  # footprints of everything placed
        self.keepout: list[Any] = []  # doorway approaches
        self._solid = None

    # -- walls ---------------------------------------------------------------------------------
    def outer(self, corners: Sequence[tuple[float, float]], doors: dict[int, list[float]], windows: int = 3) -> None:
        """Outer walls along the closed CCW polygon ``corners``; ``doors[k]``: positions (m from the
        edge's first corner) of closed doors in edge ``k``; up to ``windows`` windows elsewhere."""
        from app.worlds import Opening, Wall, WorldObject

        n = len(corners)
        names = ["outer"] * n
        edges = []
        for k in range(n):
            a, b = np.array(corners[k], float), np.array(corners[(k + 1) % n], float)
            L = float(np.hypot(*(b - a)))
            d = (b - a) / L
            edges.append((a - d * T_OUT / 2, b + d * T_OUT / 2, L))
        taken: dict[int, list[tuple[float, float]]] = {k: [(s - 0.5, s + 0.5) for s in doors.get(k, [])] for k in range(n)}
        wins: dict[int, list[tuple[float, float]]] = {k: [] for k in range(n)}
        for _ in range(windows):
            k = int(self.rng.integers(n))
            L = edges[k][2]
            w = round(float(self.rng.uniform(1.0, 1.6)), 1)
            if L < w + 1.4:
                continue
            s0 = float(self.rng.uniform(0.7, L - 0.7 - w))
            if all(s0 + w + 0.3 < t0 or s0 > t1 + 0.3 for t0, t1 in taken[k] + wins[k]):
                wins[k].append((s0, s0 + w))
        for k in range(n):
            a2, b2, L = edges[k]
            ops = [Opening(s0 + T_OUT / 2, s1 + T_OUT / 2, 0.0, 2.1, "door") for s0, s1 in taken[k]]
            ops += [Opening(s0 + T_OUT / 2, s1 + T_OUT / 2, round(float(self.rng.uniform(0.8, 1.0)), 2), 2.1, "window") for s0, s1 in wins[k]]
            wall = Wall((float(a2[0]), float(a2[1])), (float(b2[0]), float(b2[1])), T_OUT, WALL_H,
                        tuple(sorted(ops, key=lambda o: o.start)), name=f"{names[k]} {k}")
            self.world.walls.append(wall)
            for s in doors.get(k, []):
                self._door(wall, s + T_OUT / 2)

    def inner(self, a: tuple[float, float], b: tuple[float, float], passages: Sequence[float] = (), doors: Sequence[float] = (),
              name: str = "partition") -> None:
        """An interior wall ``a → b`` with open doorways (0.95 m) and closed doors (1.0 m) centred at
        the given distances from ``a``."""
        from app.worlds import Opening, Wall

        ops = [Opening(s - 0.475, s + 0.475, 0.0, 2.1, "passage") for s in passages]
        ops += [Opening(s - 0.5, s + 0.5, 0.0, 2.1, "door") for s in doors]
        wall = Wall((float(a[0]), float(a[1])), (float(b[0]), float(b[1])), T_IN, WALL_H, tuple(sorted(ops, key=lambda o: o.start)), name=name)
        self.world.walls.append(wall)
        for s in passages:
            self.keepout.append(Point(wall.point_at(s)).buffer(0.8))
        for s in doors:
            self._door(wall, s)

    def _door(self, wall: Any, s: float) -> None:
        from app.worlds import WorldObject
        from app.worlds import _pick_color

        px, py = wall.point_at(s)
        self.world.objects.append(WorldObject("door", "door", px, py, wall.yaw + math.pi / 2, 1.0, _pick_color(self.rng, "door")))
        self.placed.append(Polygon(self.world.objects[-1].footprint()))
        self.keepout.append(Point(px, py).buffer(0.6))

    def zone(self, name: str, x0: float, y0: float, x1: float, y1: float) -> None:
        """A free floor rectangle (inside the walls' faces) where furniture may stand."""
        self.zones.append((name, (x0, y0, x1, y1)))

    @property
    def solid(self) -> Any:
        if self._solid is None:
            self._solid = unary_union([w.solid_polygon() for w in self.world.walls])
        return self._solid

    # -- furniture -----------------------------------------------------------------------------
    def _footprint(self, model: str, x: float, y: float, yaw: float) -> Any:
        from app.ocslam.se2 import Pose2
        from app.world_models import model_footprint

        if model.startswith("box:"):
            sx, sy, _ = (float(v) for v in model[4:].split("x"))
            local = np.array([[-sx / 2, -sy / 2], [sx / 2, -sy / 2], [sx / 2, sy / 2], [-sx / 2, sy / 2]])
        else:
            local = model_footprint(model, 1.0)
        return Polygon(Pose2(x, y, yaw).transform_points(local))

    def place(self, items: Sequence[Item], zone: tuple[float, float, float, float], *, wall: bool, tries: int = 40,
              corner: bool = False) -> bool:
        """Put a group into ``zone``: against one of its sides (``wall``; at a corner with ``corner``)
        or free-standing at a random right-angle yaw; every footprint inside the zone, off the walls
        and doorways, and ``GROUP_GAP_M`` from everything placed before."""
        from app.worlds import Obstacle, WorldObject, _pick_color

        x0, y0, x1, y1 = zone
        zpoly = Polygon([(x0, y0), (x1, y0), (x1, y1), (x0, y1)]).buffer(0.005)
        for _ in range(tries):
            if wall:
                side = int(self.rng.integers(4))
                span = (x1 - x0) if side in (0, 2) else (y1 - y0)
                u = float(self.rng.uniform(0.0, span))
                if corner:
                    u = 0.0 if self.rng.random() < 0.5 else span
                ox, oy, yaw = [(x0 + u, y0, math.pi / 2), (x1, y0 + u, math.pi), (x1 - u, y1, -math.pi / 2), (x0, y1 - u, 0.0)][side]
                if corner:  # slide the group along the wall until it touches the corner
                    pass
            else:
                ox, oy = float(self.rng.uniform(x0, x1)), float(self.rng.uniform(y0, y1))
                yaw = float(self.rng.integers(4)) * math.pi / 2 + (float(self.rng.normal(0, 0.3)) if self.rng.random() < 0.3 else 0.0)
            c, s = math.cos(yaw), math.sin(yaw)
            polys, posed = [], []
            for it in items:
                label, model, lx, ly, lyaw = it[:5]
                wx, wy = ox + c * lx - s * ly, oy + s * lx + c * ly
                polys.append(self._footprint(model, wx, wy, yaw + lyaw))
                posed.append((label, model, wx, wy, yaw + lyaw))
            if corner and wall:  # shift along the wall so the group's extreme touches the zone's corner
                g = unary_union(polys)
                gx0, gy0, gx1, gy1 = g.bounds
                dx = (x0 - gx0) if abs(ox - x0) < abs(ox - x1) else (x1 - gx1)
                dy = (y0 - gy0) if abs(oy - y0) < abs(oy - y1) else (y1 - gy1)
                dx, dy = (dx, 0.0) if side in (0, 2) else (0.0, dy)
                from shapely import affinity

                polys = [affinity.translate(p, dx, dy) for p in polys]
                posed = [(l, m, x + dx, y + dy, a) for l, m, x, y, a in posed]
            group = unary_union(polys)
            if not group.within(zpoly) or group.buffer(-0.01).intersects(self.solid):
                continue
            if wall and group.distance(self.solid) > 0.03:  # the zone's side there is open floor, not a wall
                continue
            if any(group.intersects(k) for k in self.keepout):
                continue
            if any(group.distance(p) < GROUP_GAP_M for p in self.placed):
                continue
            for label, model, wx, wy, wyaw in posed:
                if model.startswith("box:"):
                    sx, sy, sz = (float(v) for v in model[4:].split("x"))
                    self.world.obstacles.append(Obstacle("box", round(wx, 3), round(wy, 3), round(wyaw, 4), size=(sx, sy, sz),
                                                         color=(0.4, 0.3, 0.22)))
                elif label is None:
                    self.world.obstacles.append(Obstacle("model", round(wx, 3), round(wy, 3), round(wyaw, 4), model=model,
                                                         color=_pick_color(self.rng, model)))
                else:
                    self.world.objects.append(WorldObject(label, model, round(wx, 3), round(wy, 3), round(wyaw, 4), 1.0,
                                                          _pick_color(self.rng, model)))
            self.placed.append(group)
            return True
        return False

    def person_by_door(self) -> bool:
        """A person standing beside one of the doors, inside the free space, facing into the room."""
        from app.worlds import WorldObject, _pick_color

        doors = [o for o in self.world.objects if o.label == "door"]
        for _ in range(30):
            d = doors[int(self.rng.integers(len(doors)))]
            for sign in (1.0, -1.0):
                n = np.array([math.cos(d.yaw), math.sin(d.yaw)]) * sign  # across the wall
                t = np.array([-n[1], n[0]]) * (1.0 if self.rng.random() < 0.5 else -1.0)
                p = np.array([d.x, d.y]) + n * float(self.rng.uniform(0.5, 0.8)) + t * float(self.rng.uniform(0.75, 1.0))
                yaw = math.atan2(n[1], n[0]) + float(self.rng.normal(0, 0.4))
                fp = self._footprint("person", float(p[0]), float(p[1]), yaw)
                if not any(fp.within(Polygon([(z[0], z[1]), (z[2], z[1]), (z[2], z[3]), (z[0], z[3])])) for _, z in self.zones):
                    continue
                if fp.buffer(0.02).intersects(self.solid) or any(fp.distance(q) < 0.4 for q in self.placed):
                    continue
                self.world.objects.append(WorldObject("person", "person", round(float(p[0]), 3), round(float(p[1]), 3),
                                                      round(yaw, 4), 1.0, _pick_color(self.rng, "person")))
                self.placed.append(fp)
                return True
        return False

    def furnish(self, plan: Sequence[tuple[str, str]]) -> None:
        """``plan``: ``(zone name, group kind)`` to try in order (a group that does not fit is skipped)."""
        kinds: dict[str, tuple[Callable[[np.random.Generator], list[Item]], bool]] = {
            "dining": (_group_dining, False), "lounge": (_group_lounge, True), "shelves": (_group_shelves, True),
            "desk": (_group_desk, True), "clutter": (_group_clutter_pair, True)}
        zones = dict(self.zones)
        for zname, kind in plan:
            fn, wall = kinds[kind]
            self.place(fn(self.rng), zones[zname], wall=wall)

    def complete_classes(self) -> bool:
        """Add single objects until every class is present (corners, walls or free floor); a few extras."""
        from app.ocslam.messages import CLASS_NAMES

        zones = [z for _, z in self.zones]
        have = {o.label for o in self.world.objects}
        extra = int(self.rng.integers(1, 4))
        wanted = [c for c in CLASS_NAMES if c not in have] + [None] * extra
        for label in wanted:
            ok = False
            for _ in range(12):
                z = zones[int(self.rng.integers(len(zones)))]
                if label is None or self.rng.random() < 0.5:
                    cands = [s for s in _WALL_SINGLES if label is None or s[0] == label]
                    if cands:
                        lab, model, depth = cands[int(self.rng.integers(len(cands)))]
                        yaw_l = math.pi / 2 if model == "dog" else 0.0
                        if self.place([(lab, model, depth, 0.0, yaw_l)], z, wall=True, tries=10, corner=self.rng.random() < 0.4):
                            ok = True
                            break
                cands = [s for s in _FREE_SINGLES if label is None or s[0] == label]
                if cands:
                    lab, model = cands[int(self.rng.integers(len(cands)))]
                    if self.place([(lab, model, 0.0, 0.0, float(self.rng.uniform(-math.pi, math.pi)))], z, wall=False, tries=10):
                        ok = True
                        break
            if label is not None and not ok:
                return False
        return True

    def finish(self, start_zone: str, visit: Sequence[str]) -> Any:
        """Start pose in ``start_zone``, a tour through the zones' centres in ``visit`` order plus
        looks at every object (:func:`plan_look_tour`); validated, or ``None``."""
        from app.ocslam.se2 import Pose2
        from app.worlds import ROBOT_RADIUS_M, ROUTE_MARGIN_M, WorldError, _Planner, validate_world

        zones = dict(self.zones)
        planner = _Planner(self.world, ROBOT_RADIUS_M + ROUTE_MARGIN_M + 0.02, preferred=0.35, res=0.1)
        z = zones[start_zone]
        c = planner.nearest_free((z[0] + z[2]) / 2, (z[1] + z[3]) / 2, max_r=2.0)
        if c is None:
            return None
        sx, sy = planner.point(c)
        self.world.start = Pose2(round(sx, 3), round(sy, 3), round(float(self.rng.uniform(-math.pi, math.pi)), 3))
        goals = []
        for name in visit:
            z = zones[name]
            cell = planner.nearest_free((z[0] + z[2]) / 2, (z[1] + z[3]) / 2, max_r=1.5)
            if cell is not None:
                goals.append(planner.point(cell))
        route = plan_look_tour(self.world, goals, res=0.1)
        if route is None:
            return None
        self.world.routes = {"tour": route}
        try:
            validate_world(self.world)
        except WorldError:
            return None
        return self.world


def _corridor(rng: np.random.Generator, seed: int) -> Any:
    L = round(float(rng.uniform(9.0, 13.0)), 1)
    cw = round(float(rng.uniform(1.6, 2.2)), 1)
    north = round(float(rng.uniform(3.0, 4.0)), 1)
    south = round(float(rng.uniform(2.8, 3.6)), 1) if rng.random() < 0.5 else 0.0
    y0, y1 = -south, cw + north
    b = _Builder(rng, f"corridor_{seed}", seed,
                 f"corridor + offices (ocslam world random --family corridor --seed {seed}): {L} × {cw} m corridor")
    # corners CCW from (0, y0); edge 0: south, 1: east, 2: north, 3: west; corridor doors at both ends
    h = y1 - y0
    b.outer([(0.0, y0), (L, y0), (L, y1), (0.0, y1)], {1: [cw / 2 - y0], 3: [y1 - cw / 2]}, windows=3)
    n_off = int(rng.integers(2, 4))
    cuts = np.sort(rng.uniform(0.3, 0.7, n_off - 1)) if n_off > 1 else np.array([])
    xs = [0.0] + [round(float(L * (k + c / n_off * 0 + 0) / 1), 1) for k, c in []] + [L]
    xs = [0.0] + [round(float((k + 1) * L / n_off + rng.uniform(-0.6, 0.6)), 1) for k in range(n_off - 1)] + [L]
    passages, side_doors = [], []
    for k in range(n_off):
        a, c = xs[k], xs[k + 1]
        s = float(rng.uniform(a + 0.8, c - 0.8))
        passages.append(round(s, 2))
        b.zone(f"office N{k}", a + T_IN / 2 if k else T_OUT / 2, cw + T_IN / 2, c - T_IN / 2 if k < n_off - 1 else L - T_OUT / 2, y1 - T_OUT / 2)
    for k in range(1, n_off):
        b.inner((xs[k], cw), (xs[k], y1))
    # a closed door along the corridor's south wall (a closet or another flat), an office door or two
    s_doors = []
    s_pass = []
    if south > 0:
        m = int(rng.integers(1, 3))
        sx = [0.0] + [round(float((k + 1) * L / m + rng.uniform(-0.5, 0.5)), 1) for k in range(m - 1)] + [L]
        for k in range(m):
            s_pass.append(round(float(rng.uniform(sx[k] + 0.8, sx[k + 1] - 0.8)), 2))
            b.zone(f"office S{k}", sx[k] + T_IN / 2 if k else T_OUT / 2, y0 + T_OUT / 2, sx[k + 1] - T_IN / 2 if k < m - 1 else L - T_OUT / 2, -T_IN / 2)
        for k in range(1, m):
            b.inner((sx[k], y0), (sx[k], 0.0))
    else:
        for _ in range(int(rng.integers(1, 3))):
            s = round(float(rng.uniform(1.5, L - 1.5)), 2)
            if all(abs(s - t) > 1.6 for t in s_doors):
                s_doors.append(s)
    b.inner((0.0, cw), (L, cw), passages=passages, name="corridor north")
    if south > 0:
        b.inner((0.0, 0.0), (L, 0.0), passages=s_pass, name="corridor south")
    else:
        # the south outer wall is the corridor's; its doors are added as closed doors in an inner wall
        # lying on it would overlap, so they go into the outer wall: rebuild it with the doors
        from app.worlds import Opening, Wall

        w0 = b.world.walls[0]
        ops = tuple(sorted(list(w0.openings) + [Opening(s - 0.5 + T_OUT / 2, s + 0.5 + T_OUT / 2, 0.0, 2.1, "door") for s in s_doors],
                           key=lambda o: o.start))
        if all(o1.end <= o2.start for o1, o2 in zip(ops, ops[1:])):
            b.world.walls[0] = Wall(w0.start, w0.end, w0.thickness, w0.height, ops, name=w0.name)
            b._solid = None
            for s in s_doors:
                b._door(b.world.walls[0], s + T_OUT / 2)
    b.zone("corridor", T_OUT / 2, (T_OUT if south == 0 else T_IN) / 2, L - T_OUT / 2, cw - T_IN / 2)
    offices = [n for n, _ in b.zones if n.startswith("office")]
    plan = []
    for n in offices:
        plan.append((n, ["desk", "dining", "shelves", "lounge"][int(rng.integers(4))]))
        if rng.random() < 0.5:
            plan.append((n, ["shelves", "clutter", "desk"][int(rng.integers(3))]))
    plan += [("corridor", "clutter")]
    b.furnish(plan)
    b.person_by_door()
    if not b.complete_classes():
        return None
    order = ["corridor"] + offices + ["corridor"]
    return b.finish("corridor", order)


def _lshape(rng: np.random.Generator, seed: int) -> Any:
    W = round(float(rng.uniform(8.0, 11.0)), 1)
    H = round(float(rng.uniform(7.0, 9.0)), 1)
    w1 = round(float(rng.uniform(0.4, 0.55) * W), 1)  # the north arm's width
    h1 = round(float(rng.uniform(0.4, 0.55) * H), 1)  # the south arm's height
    b = _Builder(rng, f"lshape_{seed}", seed, f"L-shaped flat (ocslam world random --family lshape --seed {seed}): {W} × {H} m")
    corners = [(0.0, 0.0), (W, 0.0), (W, h1), (w1, h1), (w1, H), (0.0, H)]
    doors = {int(rng.choice([0, 1])): [round(float(rng.uniform(1.0, (W if True else h1) - 1.0) if False else rng.uniform(0.8, 2.0)), 2)]}
    if rng.random() < 0.6:
        doors[4] = [round(float(rng.uniform(0.8, w1 - 0.8)), 2)]  # north edge (from (w1, H) to (0, H))
    b.outer(corners, doors, windows=4)
    # a bedroom in the north arm's end, behind a partition with a doorway (or a closed door)
    bed_y = round(float(rng.uniform(h1 + 2.4, H - 2.6)), 1) if H - h1 > 5.0 else None
    if bed_y is not None:
        s = round(float(rng.uniform(0.8, w1 - 0.8)), 2)
        b.inner((0.0, bed_y), (w1, bed_y), passages=[s], name="bedroom wall")
        b.zone("bedroom", T_OUT / 2, bed_y + T_IN / 2, w1 - T_OUT / 2, H - T_OUT / 2)
        b.zone("north arm", T_OUT / 2, h1 + 0.2, w1 - T_OUT / 2, bed_y - T_IN / 2)
    else:
        b.zone("north arm", T_OUT / 2, h1 + 0.2, w1 - T_OUT / 2, H - T_OUT / 2)
    b.zone("south arm", T_OUT / 2, T_OUT / 2, W - T_OUT / 2, h1 - T_OUT / 2)
    # the kitchen: a counter run against the east end
    from app.worlds import Obstacle

    if rng.random() < 0.8:
        cy = float(rng.uniform(1.3, max(1.31, h1 - 1.3)))
        g = b._footprint("kitchen_counter", W - T_OUT / 2 - 0.355, cy, math.pi)
        if g.within(Polygon([(0, 0), (W, 0), (W, h1), (0, h1)]).buffer(-0.1)) and not g.buffer(-0.01).intersects(b.solid) \
                and not any(g.intersects(k) for k in b.keepout):
            b.world.obstacles.append(Obstacle("model", round(W - T_OUT / 2 - 0.355, 3), round(cy, 3), math.pi, model="kitchen_counter"))
            b.placed.append(g)
    plan = [("south arm", "dining"), ("north arm", "lounge"), ("south arm", "shelves"), ("north arm", "clutter")]
    if bed_y is not None:
        plan += [("bedroom", "shelves"), ("bedroom", "desk")]
    b.furnish(plan)
    b.person_by_door()
    if not b.complete_classes():
        return None
    visit = ["south arm", "north arm"] + (["bedroom"] if bed_y is not None else []) + ["south arm"]
    return b.finish("south arm", visit)


def _openplan(rng: np.random.Generator, seed: int) -> Any:
    W = round(float(rng.uniform(8.0, 12.0)), 1)
    H = round(float(rng.uniform(6.0, 8.0)), 1)
    b = _Builder(rng, f"openplan_{seed}", seed, f"open-plan flat (ocslam world random --family openplan --seed {seed}): {W} × {H} m")
    doors: dict[int, list[float]] = {int(rng.integers(4)): []}
    k = next(iter(doors))
    L = W if k in (0, 2) else H
    doors[k] = [round(float(rng.uniform(0.9, L - 0.9)), 2)]
    b.outer([(0.0, 0.0), (W, 0.0), (W, H), (0.0, H)], doors, windows=4)
    # one or two partition stubs from a wall split the space into zones without closing them
    stub_x = round(float(rng.uniform(0.4, 0.6) * W), 1)
    stub_len = round(float(rng.uniform(1.5, min(3.0, H - 3.0))), 1)
    if rng.random() < 0.5:
        b.inner((stub_x, H), (stub_x, H - stub_len), name="partition stub")
    else:
        b.inner((stub_x, 0.0), (stub_x, stub_len), name="partition stub")
    b.zone("west", T_OUT / 2, T_OUT / 2, stub_x - T_IN / 2, H - T_OUT / 2)
    b.zone("east", stub_x + T_IN / 2, T_OUT / 2, W - T_OUT / 2, H - T_OUT / 2)
    from app.worlds import Obstacle

    for model in ("kitchen_counter", "fridge", "tv_stand"):
        b.place([(None, model, 0.36 if model != "tv_stand" else 0.2, 0.0, 0.0)], dict(b.zones)["east" if model != "tv_stand" else "west"],
                wall=True, tries=20)
    plan = [("east", "dining"), ("west", "lounge"), ("west", "shelves"), ("east", "clutter"), ("west", "clutter")]
    if rng.random() < 0.5:
        plan.append(("east", "desk"))
    b.furnish(plan)
    b.person_by_door()
    if not b.complete_classes():
        return None
    return b.finish("east", ["east", "west", "east"])


#: family name → builder ``(rng, seed) → World | None``; ``rooms`` is :func:`app.worlds.random_world`'s own
FAMILIES: dict[str, Callable[[np.random.Generator, int], Any]] = {"corridor": _corridor, "lshape": _lshape, "openplan": _openplan}


def generate(family: str, seed: int, attempts: int = 30) -> Any:
    """A valid world of a layout family (``corridor``, ``lshape``, ``openplan``; ``rooms`` goes to
    :func:`app.worlds.random_world`). Deterministic for ``(family, seed)``; ``WorldError`` if no
    attempt gave a valid world."""
    from app.worlds import WorldError, random_world

    if family == "rooms":
        return random_world(seed)
    if family not in FAMILIES:
        raise WorldError(f"unknown layout family {family!r} (families: rooms, {', '.join(FAMILIES)})")
    rng = np.random.default_rng([seed, sorted(FAMILIES).index(family) + 1])
    for _ in range(attempts):
        w = FAMILIES[family](rng, seed)
        if w is not None:
            return w
    raise WorldError(f"world random --family {family} --seed {seed}: no valid world in {attempts} attempts")
