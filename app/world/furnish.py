"""Furnishing generated worlds: walls, zones and groups of furniture (for :mod:`app.world.layouts`).

Groups look like places people live and work in: a table with chairs pushed in around it, a
sofa + armchair + low table, a row of shelves, a desk, a person by a door; singles stand along walls
or in the open. :class:`Builder` holds one world being built (world frame, radians) and plans its
``tour`` (:class:`app.world.planner.Planner`) when it is done.

Example:
    >>> b = Builder(np.random.default_rng(1), "flat", 1, "a flat")
    >>> b.outer([(0, 0), (6, 0), (6, 5), (0, 5)], {0: [2.0]})
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from shapely.geometry import Point, Polygon
from shapely.ops import unary_union

from app.world.models.colors import FLOOR_COLORS, WALL_COLORS, pick_color
from app.world.models.geometry import model_footprint
from app.world.tour import plan_look_tour, tour_planner
from app.world.types import (
    Obstacle,
    Opening,
    Wall,
    World,
    WorldError,
    WorldObject,
)
from app.world.validation import validate_world

__all__ = ["Builder", "GROUP_GAP_M"]

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


class Builder:
    """Walls, zones and furniture of one generated world (world frame, radians)."""

    def __init__(self, rng: np.random.Generator, name: str, seed: int, description: str) -> None:
        self.rng = rng
        self.world = World(name=name, description=description, seed=int(seed),
                           floor_color=FLOOR_COLORS[int(rng.integers(len(FLOOR_COLORS)))], wall_color=WALL_COLORS[int(rng.integers(len(WALL_COLORS)))])
        self.zones: list[tuple[str, tuple[float, float, float, float]]] = []
        self.placed: list[Any] = []  # footprints of everything placed
        self.keepout: list[Any] = []  # doorway approaches
        self._solid = None

    # -- walls ---------------------------------------------------------------------------------
    def outer(self, corners: Sequence[tuple[float, float]], doors: dict[int, list[float]], windows: int = 3) -> None:
        """Outer walls along the closed CCW polygon ``corners``; ``doors[k]``: positions (m from the
        edge's first corner) of closed doors in edge ``k``; up to ``windows`` windows elsewhere."""
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
            hi = L - 0.7 - w  # the last start that leaves 0.7 m of wall at each end
            if L < w + 1.4 or hi < 0.7:  # an edge of exactly w + 1.4 m may round either way in each test
                continue
            s0 = float(self.rng.uniform(0.7, hi))
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
        ops = [Opening(s - 0.475, s + 0.475, 0.0, 2.1, "passage") for s in passages]
        ops += [Opening(s - 0.5, s + 0.5, 0.0, 2.1, "door") for s in doors]
        wall = Wall((float(a[0]), float(a[1])), (float(b[0]), float(b[1])), T_IN, WALL_H, tuple(sorted(ops, key=lambda o: o.start)), name=name)
        self.world.walls.append(wall)
        for s in passages:
            self.keepout.append(Point(wall.point_at(s)).buffer(0.8))
        for s in doors:
            self._door(wall, s)

    def _door(self, wall: Any, s: float) -> None:
        px, py = wall.point_at(s)
        self.world.objects.append(WorldObject("door", "door", px, py, wall.yaw + math.pi / 2, 1.0, pick_color(self.rng, "door")))
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
                posed = [(lab, m, x + dx, y + dy, a) for lab, m, x, y, a in posed]
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
                                                         color=pick_color(self.rng, model)))
                else:
                    self.world.objects.append(WorldObject(label, model, round(wx, 3), round(wy, 3), round(wyaw, 4), 1.0,
                                                          pick_color(self.rng, model)))
            self.placed.append(group)
            return True
        return False

    def person_by_door(self) -> bool:
        """A person standing beside one of the doors, inside the free space, facing into the room."""
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
                                                      round(yaw, 4), 1.0, pick_color(self.rng, "person")))
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
        zones = dict(self.zones)
        planner = tour_planner(self.world, res=0.1)
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
        route = plan_look_tour(self.world, goals, res=0.1, planner=planner)
        if route is None:
            return None
        self.world.routes = {"tour": route}
        try:
            validate_world(self.world)
        except WorldError:
            return None
        return self.world
