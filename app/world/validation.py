"""World validation and limits: counts and sizes a world may have, and its geometry check.

:func:`check_world_limits` runs on the parsed YAML mapping before anything is built from it;
:func:`validate_world` checks a built :class:`~app.world.types.World` (walls, overlaps, inside the
walls, start pose, routes) and raises :class:`~app.world.types.WorldError` naming the first
offending entry.

Example:
    >>> validate_world(load_world("assets/worlds/apartment.yaml", validate=False))   # None: valid
"""

from __future__ import annotations

from typing import Any

import numpy as np
import shapely
from shapely.geometry import LineString, Point, Polygon
from shapely.ops import unary_union

from app.ocslam.messages import CLASS_NAMES
from app.world.models.catalogue import MODELS
from app.world.types import (
    OVERLAP_TOL_M,
    ROBOT_HEIGHT_M,
    ROBOT_RADIUS_M,
    ROUTE_MARGIN_M,
    World,
    WorldError,
    object_entry_name,
    obstacle_entry_name,
    wall_entry_name,
)

__all__ = [
    "MAX_WALLS",
    "MAX_ENTITIES",
    "MAX_OPENINGS",
    "MAX_ROUTES",
    "MAX_WAYPOINTS",
    "MAX_COORD_M",
    "MAX_SIZE_M",
    "MAX_FILE_BYTES",
    "check_world_limits",
    "validate_world",
    "world_region",
]

# Limits, checked before anything heavy (the simulator's memory and time grow with these)

#: walls in a world
MAX_WALLS = 500
#: objects and obstacles together
MAX_ENTITIES = 500
#: openings in one wall
MAX_OPENINGS = 50
#: named routes, and waypoints in one route
MAX_ROUTES = 50
MAX_WAYPOINTS = 2000
#: every coordinate (walls, obstacles, objects, start, waypoints) lies within ±MAX_COORD_M
MAX_COORD_M = 500.0
#: every size (wall thickness/height, box sides, cylinder diameter/height, scaled models, lifts)
MAX_SIZE_M = 50.0
#: world files larger than this are refused before they are parsed (a world at every limit is ~0.1 MiB)
MAX_FILE_BYTES = 2 * 2**20


def check_world_limits(d: dict) -> None:
    """Counts of a parsed world mapping against the limits (:data:`MAX_WALLS`, :data:`MAX_ENTITIES`,
    :data:`MAX_ROUTES`, :data:`MAX_WAYPOINTS`), before anything is built from it. ``WorldError`` otherwise."""
    n: dict[str, int] = {}
    for key in ("walls", "obstacles", "objects"):
        v = d.get(key)
        n[key] = len(v) if isinstance(v, list) else 0
    if n["walls"] > MAX_WALLS:
        raise WorldError(f"walls: {n['walls']} walls; a world may have at most {MAX_WALLS}")
    if n["obstacles"] + n["objects"] > MAX_ENTITIES:
        raise WorldError(f"{n['objects']} objects and {n['obstacles']} obstacles; a world may have at most "
                         f"{MAX_ENTITIES} objects and obstacles together")
    for i, w in enumerate(d.get("walls") or []):
        if isinstance(w, dict) and isinstance(w.get("openings"), list) and len(w["openings"]) > MAX_OPENINGS:
            raise WorldError(f"walls[{i}].openings: {len(w['openings'])} openings; a wall may have at most {MAX_OPENINGS}")
    routes = d.get("routes")
    if isinstance(routes, dict):
        if len(routes) > MAX_ROUTES:
            raise WorldError(f"routes: {len(routes)} routes; a world may have at most {MAX_ROUTES}")
        for name, pts in routes.items():
            if isinstance(pts, list) and len(pts) > MAX_WAYPOINTS:
                raise WorldError(f"routes[{name!r}]: {len(pts)} waypoints; a route may have at most {MAX_WAYPOINTS}")


def _overlaps(a: Any, b: Any, tol: float = OVERLAP_TOL_M) -> bool:
    """True if ``a`` and ``b`` interpenetrate by more than ``tol`` (touching is fine)."""
    if a.is_empty or b.is_empty or not a.intersects(b):
        return False
    inter = a.intersection(b)
    if inter.is_empty or inter.area <= 0:
        return False
    return not inter.buffer(-tol / 2).is_empty


def _first_overlaps(geoms: list[Any], others: list[Any] | None = None, tol: float = OVERLAP_TOL_M) -> dict[int, list[int]]:
    """``{i: [j, …]}`` (sorted) of the pairs that interpenetrate (:func:`_overlaps`): ``geoms[i]`` with
    ``others[j]``, or with an earlier ``geoms[j]`` (j < i) when ``others`` is None. Candidates from an
    STRtree, so n entries cost O(n log n) instead of n² exact tests."""
    target = geoms if others is None else others
    out: dict[int, list[int]] = {}
    if not geoms or not target:
        return out
    tree = shapely.STRtree(target)
    ii, jj = tree.query(geoms, predicate="intersects")
    for i, j in sorted(zip(ii.tolist(), jj.tolist())):
        if others is None and j >= i:
            continue
        if _overlaps(geoms[i], target[j], tol):
            out.setdefault(i, []).append(j)
    return out


def world_region(world: World) -> Any:
    """The area inside the walls: every area the walls enclose (doors, windows and passages closed; gaps
    up to 5 cm at corners closed), with the walls themselves (2.5 cm thicker). Empty if the walls enclose
    nothing."""
    grown = shapely.buffer(np.array([w.polygon() for w in world.walls], dtype=object), 0.025, join_style="mitre")
    walls = shapely.union_all(grown)  # each wall 2.5 cm thicker: corner gaps up to 5 cm close
    parts = list(getattr(walls, "geoms", [walls]))
    filled = [Polygon(g.exterior) for g in parts if isinstance(g, Polygon) and not g.is_empty and len(g.interiors)]
    if not filled:
        return Polygon()
    filled += [Polygon(g.exterior) for g in parts if isinstance(g, Polygon) and not len(g.interiors)]
    return unary_union(filled)


def validate_world(world: World, *, robot_radius: float = ROBOT_RADIUS_M, route_margin: float = ROUTE_MARGIN_M) -> None:
    """Check the geometry; raise :class:`WorldError` naming the first offending entry.

    Limits: at most :data:`MAX_WALLS` walls and :data:`MAX_ENTITIES` objects and obstacles, coordinates
    within ±:data:`MAX_COORD_M`. Walls: positive length, openings inside the wall. Objects: no overlap
    with a wall's solid part, an obstacle or another object (doors may fill a floor-level door opening),
    and inside the walls (in an area they enclose). Start: inside the walls, the robot's disc free.
    Routes: every segment keeps ``robot_radius + route_margin`` from everything. Candidate pairs come
    from STRtrees, so a world at the limits validates in well under a second.
    """
    if not world.walls:
        raise WorldError("walls: a world needs at least one wall")
    check_world_limits({"walls": world.walls, "obstacles": world.obstacles, "objects": world.objects, "routes": world.routes})
    for i, w in enumerate(world.walls):
        name = wall_entry_name(i, w)
        for k, v in (("from", w.start), ("to", w.end)):
            if max(abs(v[0]), abs(v[1])) > MAX_COORD_M:
                raise WorldError(f"{name}: '{k}' {list(v)} is beyond ±{MAX_COORD_M:g} m")
        if w.length < 1e-6:
            raise WorldError(f"{name}: 'from' and 'to' are the same point")
        for j, o in enumerate(w.openings):
            if not (0 <= o.start < o.end <= w.length + 1e-9):
                raise WorldError(f"{name}.openings[{j}]: [{o.start}, {o.end}] must lie within the wall (length {w.length:.3f} m)")
            if not (0 <= o.bottom < o.top):
                raise WorldError(f"{name}.openings[{j}]: bottom {o.bottom} must be below top {o.top}")
        spans = sorted((o.start, o.end) for o in w.openings)
        for (a0, a1), (b0, b1) in zip(spans, spans[1:]):
            if b0 < a1 - 1e-9:
                raise WorldError(f"{name}: openings [{a0}, {a1}] and [{b0}, {b1}] overlap")
    for i, o in enumerate(world.obstacles):
        if max(abs(o.x), abs(o.y)) > MAX_COORD_M:
            raise WorldError(f"{obstacle_entry_name(i, o)}: ({o.x}, {o.y}) is beyond ±{MAX_COORD_M:g} m")
        if o.shape == "model" and o.model not in MODELS:
            raise WorldError(f"{obstacle_entry_name(i, o)}: unknown model {o.model!r}")
    for i, o in enumerate(world.objects):
        name = object_entry_name(i, o)
        if max(abs(o.x), abs(o.y)) > MAX_COORD_M:
            raise WorldError(f"{name}: ({o.x}, {o.y}) is beyond ±{MAX_COORD_M:g} m")
        if o.label not in CLASS_NAMES:
            raise WorldError(f"{name}: unknown class {o.label!r}")
        if o.model not in MODELS:
            raise WorldError(f"{name}: unknown model {o.model!r}")
        if MODELS[o.model].label != o.label:
            raise WorldError(f"{name}: model {o.model!r} is of class {MODELS[o.model].label!r}")
    wall_names = [wall_entry_name(i, w) for i, w in enumerate(world.walls)]
    wall_geoms = [w.solid_polygon() for w in world.walls]
    wall_idx = [k for k, g in enumerate(wall_geoms) if not g.is_empty]
    # obstacles first, then objects, each against the walls and everything placed before it
    names = [obstacle_entry_name(i, o) for i, o in enumerate(world.obstacles)] + [object_entry_name(i, o) for i, o in enumerate(world.objects)]
    geoms = [Polygon(o.footprint()) for o in world.obstacles] + [Polygon(o.footprint()) for o in world.objects]
    bad_wall = _first_overlaps(geoms, [wall_geoms[k] for k in wall_idx])
    bad_prev = _first_overlaps(geoms)
    for i in sorted(set(bad_wall) | set(bad_prev)):
        if i in bad_wall:
            raise WorldError(f"{names[i]}: overlaps {wall_names[wall_idx[bad_wall[i][0]]]}")
        raise WorldError(f"{names[i]}: overlaps {names[bad_prev[i][0]]}")
    region = world_region(world)
    inside = shapely.covers(region, shapely.points([(o.x, o.y) for o in world.objects])) if world.objects else np.zeros(0, bool)
    for i in np.flatnonzero(~np.asarray(inside, bool)).tolist()[:1]:
        o = world.objects[i]
        why = "the walls enclose no area" if region.is_empty else "not in any area the walls enclose"
        raise WorldError(f"{object_entry_name(i, o)}: at ({o.x:.3f}, {o.y:.3f}) is outside every room ({why})")
    if not region.covers(Point(world.start.x, world.start.y)):
        why = "the walls enclose no area" if region.is_empty else "not in any area the walls enclose"
        raise WorldError(f"start: the robot at ({world.start.x:.3f}, {world.start.y:.3f}) is outside the walls ({why})")
    # = world.blocking_geometry(), from the polygons built above
    n_obs = len(world.obstacles)
    b_names = [wall_names[k] for k in wall_idx] + [names[i] for i, o in enumerate(world.obstacles) if o.z_range()[0] < ROBOT_HEIGHT_M]
    b_geoms = [wall_geoms[k] for k in wall_idx] + [geoms[i] for i, o in enumerate(world.obstacles) if o.z_range()[0] < ROBOT_HEIGHT_M]
    b_names += names[n_obs:]
    b_geoms += geoms[n_obs:]
    tree = shapely.STRtree(b_geoms) if b_geoms else None
    disc = Point(world.start.x, world.start.y).buffer(robot_radius, 32)
    if tree is not None:
        for k in sorted(tree.query(disc, predicate="intersects").tolist()):
            if _overlaps(disc, b_geoms[k], tol=1e-4):
                raise WorldError(f"start: the robot at ({world.start.x:.3f}, {world.start.y:.3f}) overlaps {b_names[k]}")
    clearance = robot_radius + route_margin

    def near(geom: Any) -> list[int]:
        """Blocking entries closer than the clearance to ``geom``, in blocking order."""
        if tree is None:
            return []
        cand = sorted(tree.query(geom, predicate="dwithin", distance=clearance).tolist())
        return [k for k in cand if b_geoms[k].distance(geom) < clearance - 1e-9]

    for rname, pts in world.routes.items():
        for k, (x, y) in enumerate(pts):
            d = Point(x, y)
            hits = near(d)
            if hits:
                bg, bn = b_geoms[hits[0]], b_names[hits[0]]
                raise WorldError(
                    f"routes[{rname!r}][{k}]: waypoint ({x:.3f}, {y:.3f}) is {bg.distance(d):.3f} m from {bn} "
                    f"(needs {clearance:.3f} m)"
                )
        seq = [(world.start.x, world.start.y)] + list(pts) if pts else []
        for k in range(1, len(seq)):
            seg = LineString([seq[k - 1], seq[k]]) if seq[k - 1] != seq[k] else Point(seq[k])
            hits = near(seg)
            if hits:
                dist = b_geoms[hits[0]].distance(seg)
                frm = "start" if k == 1 else f"[{k - 2}]"
                raise WorldError(
                    f"routes[{rname!r}]: segment {frm} → [{k - 1}] passes {dist:.3f} m from {b_names[hits[0]]} (needs {clearance:.3f} m)"
                )
