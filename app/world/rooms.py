"""The ``rooms`` layout family: a rectangle split into rooms joined by doorways (``world random``'s default).

The world is a rectangle of 7–11 × 5–8 m split into 3–5 rooms joined by doorways; outer walls
carry windows and closed doors (class ``door``); objects stand along walls and in the open, with
room for the robot to pass. The ``tour`` route (:class:`app.world.planner.Planner`) starts at the
robot and visits every room. Other families: :mod:`app.world.layouts`; the entry point for all of
them is :func:`app.world.generator.random_world`.

Example:
    >>> w = rooms_world(3)
    >>> len(w.routes["tour"]) > 0
    True
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from shapely.geometry import LineString, Point, Polygon
from shapely.geometry import box as shapely_box
from shapely.ops import unary_union

from app.ocslam.messages import CLASS_NAMES
from app.ocslam.se2 import Pose2
from app.world.models.catalogue import get_model, models_for_class
from app.world.models.colors import FLOOR_COLORS, WALL_COLORS, pick_color
from app.world.models.geometry import model_footprint
from app.world.planner import Planner
from app.world.types import (
    ROBOT_RADIUS_M,
    ROUTE_MARGIN_M,
    Obstacle,
    Opening,
    Wall,
    World,
    WorldError,
    WorldObject,
)
from app.world.validation import validate_world

__all__ = ["rooms_world", "Room"]


@dataclass
class Room:
    x0: float
    y0: float
    x1: float
    y1: float

    @property
    def poly(self) -> Polygon:
        return shapely_box(self.x0, self.y0, self.x1, self.y1)

    @property
    def center(self) -> tuple[float, float]:
        return ((self.x0 + self.x1) / 2, (self.y0 + self.y1) / 2)


def _split_rooms(rng: np.random.Generator, W: float, H: float, n_target: int) -> list[Room]:
    rooms = [Room(0.0, 0.0, W, H)]
    tries = 0
    while len(rooms) < n_target and tries < 50:
        tries += 1
        rooms.sort(key=lambda r: -(r.x1 - r.x0) * (r.y1 - r.y0))
        r = rooms[0]
        w, h = r.x1 - r.x0, r.y1 - r.y0
        vertical = w >= h if abs(w - h) > 0.5 else bool(rng.random() < 0.5)
        span = w if vertical else h
        if span < 5.0:
            continue
        cut = float(rng.uniform(0.38, 0.62)) * span
        cut = round(cut * 10) / 10
        if vertical:
            a, b = Room(r.x0, r.y0, r.x0 + cut, r.y1), Room(r.x0 + cut, r.y0, r.x1, r.y1)
        else:
            a, b = Room(r.x0, r.y0, r.x1, r.y0 + cut), Room(r.x0, r.y0 + cut, r.x1, r.y1)
        rooms[0:1] = [a, b]
    return rooms


def _shared_edge(a: Room, b: Room) -> tuple[str, float, float, float] | None:
    """('v', x, y0, y1) or ('h', y, x0, x1) if the rooms share a wall segment."""
    eps = 1e-6
    for r1, r2 in ((a, b), (b, a)):
        if abs(r1.x1 - r2.x0) < eps:
            lo, hi = max(r1.y0, r2.y0), min(r1.y1, r2.y1)
            if hi - lo > 1.9:
                return ("v", r1.x1, lo, hi)
        if abs(r1.y1 - r2.y0) < eps:
            lo, hi = max(r1.x0, r2.x0), min(r1.x1, r2.x1)
            if hi - lo > 1.9:
                return ("h", r1.y1, lo, hi)
    return None


def rooms_world(seed: int, *, n_rooms: int | None = None, extra_objects: int | None = None) -> World:
    """A randomized, valid apartment of the rooms family (see the module docstring). ``n_rooms``:
    rooms to split the rectangle into (default 3–5 at random); ``extra_objects``: objects beyond one
    of each class. Deterministic for a seed; ``WorldError`` after 40 failed attempts."""
    rng = np.random.default_rng(seed)
    for _attempt in range(40):
        w = _try_rooms_world(rng, seed, n_rooms, extra_objects)
        if w is not None:
            try:
                validate_world(w)
            except WorldError:
                continue
            return w
    raise WorldError(f"random_world(seed={seed}): could not build a valid world in 40 attempts")


def _try_rooms_world(rng: np.random.Generator, seed: int, n_rooms: int | None, extra_objects: int | None) -> World | None:
    W = round(float(rng.uniform(7.0, 11.0)), 1)
    H = round(float(rng.uniform(5.0, 8.0)), 1)
    n = n_rooms if n_rooms is not None else int(rng.integers(3, 6))
    rooms = _split_rooms(rng, W, H, n)
    t_out, t_in, height = 0.3, 0.15, 2.4
    walls: list[Wall] = []
    objects: list[WorldObject] = []
    obstacles: list[Obstacle] = []

    # -- outer walls (counter-clockwise), with windows and door openings ------------------------
    corners = [(0.0, 0.0), (W, 0.0), (W, H), (0.0, H)]
    outer_openings: list[list[Opening]] = [[], [], [], []]
    door_slots = []
    for k in range(4):
        a, b = corners[k], corners[(k + 1) % 4]
        L = math.hypot(b[0] - a[0], b[1] - a[1])
        # reserve free spans, 1.0 m doors and 1.0–1.6 m windows
        taken: list[tuple[float, float]] = []
        wants = []
        if rng.random() < 0.55:
            wants.append(("door", 1.0))
        for _ in range(int(rng.integers(0, 3))):
            wants.append(("window", round(float(rng.uniform(1.0, 1.6)), 1)))
        for kind, width in wants:
            for _ in range(20):
                s0 = float(rng.uniform(0.6, L - 0.6 - width))
                if all(s0 + width + 0.3 < t0 or s0 > t1 + 0.3 for t0, t1 in taken):
                    taken.append((s0, s0 + width))
                    if kind == "door":
                        outer_openings[k].append(Opening(s0, s0 + width, 0.0, 2.1, "door"))
                        door_slots.append((k, s0 + width / 2))
                    else:
                        outer_openings[k].append(Opening(s0, s0 + width, round(float(rng.uniform(0.8, 1.0)), 2), 2.1, "window"))
                    break
    names = ["south", "east", "north", "west"]
    # walls are centred on the room boundary lines, so the outer ones extend by half their thickness
    for k in range(4):
        a, b = corners[k], corners[(k + 1) % 4]
        d = np.subtract(b, a) / max(math.hypot(*np.subtract(b, a)), 1e-9)
        a2 = tuple(np.subtract(a, d * t_out / 2))
        b2 = tuple(np.add(b, d * t_out / 2))
        ops = tuple(Opening(o.start + t_out / 2, o.end + t_out / 2, o.bottom, o.top, o.kind) for o in outer_openings[k])
        walls.append(Wall((float(a2[0]), float(a2[1])), (float(b2[0]), float(b2[1])), t_out, height, ops, name=names[k]))
    # -- interior walls with doorways (a spanning tree of the room adjacency, plus maybe a loop) --
    edges = []
    for i in range(len(rooms)):
        for j in range(i + 1, len(rooms)):
            e = _shared_edge(rooms[i], rooms[j])
            if e is not None:
                edges.append((i, j, e))
    parent = list(range(len(rooms)))

    def find(u: int) -> int:
        while parent[u] != u:
            parent[u] = parent[parent[u]]
            u = parent[u]
        return u

    order = rng.permutation(len(edges))
    doorways: list[tuple[int, int, tuple]] = []
    for idx in order:
        i, j, e = edges[idx]
        if find(i) != find(j):
            parent[find(i)] = find(j)
            doorways.append((i, j, e))
        elif rng.random() < 0.3:
            doorways.append((i, j, e))
    if len({find(i) for i in range(len(rooms))}) != 1:
        return None
    doorway_points: list[tuple[float, float]] = []
    interior_segments: dict[tuple, list[Opening]] = {}
    for _i, _j, e in doorways:
        kind, c, lo, hi = e
        width = round(float(rng.uniform(0.9, 1.1)), 2)
        s0 = float(rng.uniform(0.35, (hi - lo) - width - 0.35))
        interior_segments.setdefault(e, []).append(Opening(s0, s0 + width, 0.0, 2.1, "passage"))
        mid = lo + s0 + width / 2
        doorway_points.append((c, mid) if kind == "v" else (mid, c))
    interior_doors: list[tuple[tuple, float]] = []  # (edge, s_mid): closed doors between rooms
    for _i, _j, e in edges:
        if e not in interior_segments and rng.random() < 0.5:
            # no doorway here: a closed door (like a closet's), seen from both rooms
            s0 = float(rng.uniform(0.35, (e[3] - e[2]) - 1.0 - 0.35))
            interior_segments[e] = [Opening(s0, s0 + 1.0, 0.0, 2.1, "door")]
            interior_doors.append((e, s0 + 0.5))
        interior_segments.setdefault(e, [])
    for e, ops in interior_segments.items():
        kind, c, lo, hi = e
        a, b = ((c, lo), (c, hi)) if kind == "v" else ((lo, c), (hi, c))
        walls.append(Wall(a, b, t_in, height, tuple(sorted(ops, key=lambda o: o.start)), name="partition"))
    # boundaries between rooms that share too short an edge get plain walls: make sure every room
    # boundary exists
    covered = unary_union([w.polygon() for w in walls])
    for r in rooms:
        for a, b in (((r.x0, r.y0), (r.x1, r.y0)), ((r.x1, r.y0), (r.x1, r.y1)), ((r.x1, r.y1), (r.x0, r.y1)), ((r.x0, r.y1), (r.x0, r.y0))):
            seg = LineString([a, b])
            rest = seg.difference(covered.buffer(0.01))
            if rest.length > 0.05:
                for piece in getattr(rest, "geoms", [rest]):
                    cs = list(piece.coords)
                    walls.append(Wall(cs[0], cs[-1], t_in, height, (), name="partition"))
                    covered = covered.union(walls[-1].polygon())

    world = World(
        name=f"random_{seed}",
        walls=walls,
        floor_color=FLOOR_COLORS[int(rng.integers(len(FLOOR_COLORS)))],
        wall_color=WALL_COLORS[int(rng.integers(len(WALL_COLORS)))],
        description=f"randomized apartment (ocslam world random --seed {seed}): {W} × {H} m, {len(rooms)} rooms",
        seed=int(seed),
    )
    # keep-out zones: doorway approaches (both sides) and the area in front of outer doors
    keepout = [Point(p).buffer(0.75) for p in doorway_points]
    wall_solid = unary_union([w.solid_polygon() for w in walls])
    placed: list[Polygon] = []

    # -- doors in the outer door openings ------------------------------------------------------
    for k, s_mid in door_slots:
        wall = walls[k]
        px, py = wall.point_at(s_mid + t_out / 2)
        # the door model's x axis is its thickness: perpendicular to the wall
        yaw = wall.yaw + math.pi / 2
        color = pick_color(rng, "door")
        objects.append(WorldObject("door", "door", px, py, yaw, 1.0, color))
        keepout.append(Point(px, py).buffer(0.6))

    for e, s_mid in interior_doors:
        kind, c, lo, hi = e
        px, py = (c, lo + s_mid) if kind == "v" else (lo + s_mid, c)
        yaw = 0.0 if kind == "v" else math.pi / 2  # the door's x axis crosses the wall
        objects.append(WorldObject("door", "door", px, py, yaw, 1.0, pick_color(rng, "door")))
        keepout.append(Point(px, py).buffer(0.6))

    def fits(fp: Polygon, gap: float) -> bool:
        if fp.buffer(0.02).intersects(wall_solid):
            return False
        if any(fp.intersects(k) for k in keepout):
            return False
        if any(fp.distance(p) < gap for p in placed):
            return False
        return any(fp.within(r.poly.buffer(-0.08)) for r in rooms)

    def place(label: str | None, model: str, room: Room, against_wall: bool, gap: float = 0.5) -> bool:
        scale = 1.0
        fp0 = model_footprint(model, scale)
        depth = float(fp0[:, 0].max())
        for _ in range(60):
            if against_wall:
                side = int(rng.integers(4))
                inset = 0.08 + t_in / 2 + 0.01
                if side == 0:
                    x, y, yaw = float(rng.uniform(room.x0 + 0.5, room.x1 - 0.5)), room.y0 + inset + depth, math.pi / 2
                elif side == 1:
                    x, y, yaw = room.x1 - inset - depth, float(rng.uniform(room.y0 + 0.5, room.y1 - 0.5)), math.pi
                elif side == 2:
                    x, y, yaw = float(rng.uniform(room.x0 + 0.5, room.x1 - 0.5)), room.y1 - inset - depth, -math.pi / 2
                else:
                    x, y, yaw = room.x0 + inset + depth, float(rng.uniform(room.y0 + 0.5, room.y1 - 0.5)), 0.0
            else:
                x = float(rng.uniform(room.x0 + 0.7, room.x1 - 0.7))
                y = float(rng.uniform(room.y0 + 0.7, room.y1 - 0.7))
                yaw = float(rng.uniform(-math.pi, math.pi))
            fp = Polygon(Pose2(x, y, yaw).transform_points(fp0))
            if fits(fp, gap):
                placed.append(fp)
                color = pick_color(rng, model)
                if label is None:
                    obstacles.append(Obstacle("model", x, y, yaw, model=model, color=color))
                else:
                    objects.append(WorldObject(label, model, x, y, yaw, scale, color))
                return True
        return False

    wall_models = {"shelf": True, "chair": True, "flowers": True, "extinguisher": True, "table": False, "dog": False,
                   "person": False, "gnome": True, "ball": False, "duck": False}
    for label in CLASS_NAMES:
        if label == "door":
            if not door_slots and not interior_doors:
                return None  # every world must show a door
            continue
        choices = models_for_class(label)
        model = choices[int(rng.integers(len(choices)))]
        against = wall_models.get(label, False)
        if model in ("armchair", "sofa", "sofa3", "bookshelf", "low_shelf"):
            against = True
        ok = False
        for room in rng.permutation(len(rooms)):
            if place(label, model, rooms[int(room)], against):
                ok = True
                break
        if not ok:
            return None
    # extra classified objects and unclassified furniture
    n_extra = extra_objects if extra_objects is not None else int(rng.integers(3, 8))
    pool = ["dining_chair", "armchair", "sofa", "play_ball", "soccer_ball", "potted_flowers", "low_shelf", "round_table",
            "person", "gnome", "rubber_duck", "fire_extinguisher", "dog"]
    for _ in range(n_extra):
        model = pool[int(rng.integers(len(pool)))]
        room = rooms[int(rng.integers(len(rooms)))]
        against = model in ("armchair", "sofa", "low_shelf", "potted_flowers", "fire_extinguisher")
        place(get_model(model).label, model, room, against)
    for model in ("fridge", "kitchen_counter", "tv_stand", "stool", "trash_bin", "cardboard_box"):
        if rng.random() < 0.55:
            room = rooms[int(rng.integers(len(rooms)))]
            place(None, model, room, model in ("fridge", "kitchen_counter", "tv_stand"))
    world.objects = objects
    world.obstacles = obstacles

    # -- start pose and the tour ---------------------------------------------------------------
    planner = Planner(world, ROBOT_RADIUS_M + ROUTE_MARGIN_M + 0.02, preferred=0.35)
    first = rooms[int(rng.integers(len(rooms)))]
    sc = planner.nearest_free(*first.center, max_r=2.0)
    if sc is None:
        return None
    sx, sy = planner.point(sc)
    world.start = Pose2(round(sx, 3), round(sy, 3), round(float(rng.uniform(-math.pi, math.pi)), 3))
    # visit rooms in a nearest-neighbour order, through their free centres, then come back
    remaining = [r for r in rooms if r is not first]
    order = [first]
    while remaining:
        cur = order[-1].center
        k = int(np.argmin([math.hypot(r.center[0] - cur[0], r.center[1] - cur[1]) for r in remaining]))
        order.append(remaining.pop(k))
    goals = []
    for r in order:
        goals += _room_viewpoints(planner, r, goals[-1] if goals else (sx, sy))
    goals.append((sx, sy))
    route: list[tuple[float, float]] = []
    cur = (sx, sy)
    for g in goals:
        path = planner.plan(cur, g)
        if path is None:
            return None
        for pt in path[1:]:
            route.append((round(pt[0], 3), round(pt[1], 3)))
        cur = path[-1]
    world.routes = {"tour": route}
    return world


def _room_viewpoints(planner: Planner, room: Room, cur: tuple[float, float]) -> list[tuple[float, float]]:
    """Where to drive in a room so the camera sweeps it: a loop ~0.8 m inside its walls (a line along
    a narrow room, its centre for a small one), starting nearest ``cur``."""
    inset = 0.8
    w, h = room.x1 - room.x0, room.y1 - room.y0
    cx, cy = room.center
    if w >= 2 * inset + 1.0 and h >= 2 * inset + 1.0:
        cands = [(room.x0 + inset, room.y0 + inset), (room.x1 - inset, room.y0 + inset),
                 (room.x1 - inset, room.y1 - inset), (room.x0 + inset, room.y1 - inset)]
    elif max(w, h) >= 2 * inset + 1.0:
        cands = [(room.x0 + inset, cy), (room.x1 - inset, cy)] if w > h else [(cx, room.y0 + inset), (cx, room.y1 - inset)]
    else:
        cands = [room.center]
    k = int(np.argmin([math.hypot(c[0] - cur[0], c[1] - cur[1]) for c in cands]))
    cands = cands[k:] + cands[:k]
    out = []
    for c in cands:
        cell = planner.nearest_free(*c, max_r=0.6)
        if cell is not None:
            out.append(planner.point(cell))
    return out
