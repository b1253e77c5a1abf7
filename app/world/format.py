"""World files: dataclasses, YAML load/dump, validation and random apartments (no pybullet here).

A world is walls (segments with thickness, height and openings for doors and windows), static
obstacles (boxes, cylinders or unclassified models), classified objects (``class``, ``model``,
``x``, ``y``, ``yaw``, optional ``scale`` and ``color``), the robot's start pose and named routes.
The format is documented in ``docs/world-format.md``. Frames: the world frame is ENU (x east,
y north, z up), metres. **In YAML, yaws are in degrees**; in these dataclasses they are radians.

Example:
    >>> world = load_world("assets/worlds/apartment.yaml")      # validated; WorldError otherwise
    >>> [o.label for o in world.objects][:3]
    ['ball', 'dog', 'gnome']
    >>> w = random_world(seed=3)                                 # a valid randomized apartment
    >>> dump_world(w, "/tmp/w3.yaml")
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np
import shapely
import yaml
from numpy.typing import NDArray
from shapely.geometry import LineString, Point, Polygon, box as shapely_box
from shapely.ops import unary_union

from app.config import atomic_write_text
from app.ocslam.messages import CLASS_NAMES
from app.ocslam.se2 import Pose2
from app.world_models import MODELS, get_model, model_footprint, model_z_range, models_for_class, parse_color

__all__ = [
    "WorldError",
    "Opening",
    "Wall",
    "Obstacle",
    "WorldObject",
    "World",
    "load_world",
    "dump_world",
    "world_from_dict",
    "world_to_dict",
    "validate_world",
    "random_world",
    "ROBOT_RADIUS_M",
    "ROUTE_MARGIN_M",
]

RGB = tuple[float, float, float]
#: the TurtleBot3 Burger's circumscribed radius (RobotConfig.footprint_radius_m)
ROBOT_RADIUS_M = 0.105
#: extra clearance a route segment keeps from every obstacle
ROUTE_MARGIN_M = 0.05
#: objects and walls may touch; overlaps deeper than this are errors
OVERLAP_TOL_M = 0.01
#: heights below which a floor-level opening lets the robot through (the Burger is 0.192 m tall)
ROBOT_HEIGHT_M = 0.2

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
#: libyaml's safe loader where PyYAML has it (several times faster), else the pure-Python one
_YAML_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class WorldError(ValueError):
    """A world file is malformed or inconsistent. The message names the offending entry."""


# ----------------------------------------------------------------------------------------------
# Dataclasses
# ----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Opening:
    """A hole in a wall: from ``start`` to ``end`` metres along the wall (from its first end point),
    between heights ``bottom`` and ``top``. ``kind``: ``door`` (floor level; a door model may fill it),
    ``window`` (a glass pane fills it) or ``passage`` (an open doorway)."""

    start: float
    end: float
    bottom: float = 0.0
    top: float = 2.1
    kind: str = "passage"


@dataclass(frozen=True)
class Wall:
    """A straight wall of ``thickness`` centred on the segment ``start → end``, ``height`` tall."""

    start: tuple[float, float]
    end: tuple[float, float]
    thickness: float = 0.15
    height: float = 2.4
    openings: tuple[Opening, ...] = ()
    color: RGB | None = None
    name: str = ""

    @property
    def length(self) -> float:
        return float(math.hypot(self.end[0] - self.start[0], self.end[1] - self.start[1]))

    @property
    def yaw(self) -> float:
        return float(math.atan2(self.end[1] - self.start[1], self.end[0] - self.start[0]))

    def point_at(self, s: float) -> tuple[float, float]:
        """The point ``s`` metres along the wall's centre line."""
        L = self.length or 1.0
        t = s / L
        return (self.start[0] + t * (self.end[0] - self.start[0]), self.start[1] + t * (self.end[1] - self.start[1]))

    def _span_polygon(self, s0: float, s1: float) -> Polygon:
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        h = self.thickness / 2
        pts = []
        for a, b in ((s0, -h), (s1, -h), (s1, h), (s0, h)):
            pts.append((self.start[0] + c * a - s * b, self.start[1] + s * a + c * b))
        return Polygon(pts)

    def polygon(self) -> Polygon:
        """The wall's whole footprint (openings ignored)."""
        return self._span_polygon(0.0, self.length)

    def boxes(self) -> list[tuple[float, float, float, float, float, float]]:
        """Solid pieces as boxes ``(s0, s1, z0, z1)`` along the wall, openings cut out; returned as
        ``(s0, s1, z0, z1, thickness, yaw)``."""
        cuts = sorted((max(0.0, o.start), min(self.length, o.end), o.bottom, min(o.top, self.height)) for o in self.openings)
        out = []
        s = 0.0
        for s0, s1, z0, z1 in cuts:
            if s0 > s:
                out.append((s, s0, 0.0, self.height, self.thickness, self.yaw))
            if z0 > 0:
                out.append((s0, s1, 0.0, z0, self.thickness, self.yaw))
            if z1 < self.height:
                out.append((s0, s1, z1, self.height, self.thickness, self.yaw))
            s = max(s, s1)
        if s < self.length:
            out.append((s, self.length, 0.0, self.height, self.thickness, self.yaw))
        return out

    def solid_polygon(self, z: float | None = None) -> Any:
        """Footprint of the solid wall at height ``z`` (``None``: anything from the floor to the robot's
        height, i.e. floor-level openings of any kind are cut out)."""
        pieces = []
        for s0, s1, z0, z1, _, _ in self.boxes():
            if z is None:
                if z0 < ROBOT_HEIGHT_M:
                    pieces.append(self._span_polygon(s0, s1))
            elif z0 <= z <= z1:
                pieces.append(self._span_polygon(s0, s1))
        return unary_union(pieces) if pieces else Polygon()

    def opening_polygon(self, o: Opening) -> Polygon:
        return self._span_polygon(o.start, o.end)


@dataclass(frozen=True)
class Obstacle:
    """An unclassified static obstacle: ``shape`` is ``box`` (``size`` = sx, sy, sz), ``cylinder``
    (``radius``, ``height``) or ``model`` (an unclassified catalogue model, ``scale``). ``z`` lifts it."""

    shape: str
    x: float
    y: float
    yaw: float = 0.0
    size: tuple[float, float, float] = (0.5, 0.5, 0.5)
    radius: float = 0.25
    height: float = 0.5
    z: float = 0.0
    model: str = ""
    scale: float = 1.0
    color: RGB | None = None
    name: str = ""

    def local_footprint(self) -> NDArray[np.float64]:
        if self.shape == "box":
            sx, sy = self.size[0] / 2, self.size[1] / 2
            return np.array([[-sx, -sy], [sx, -sy], [sx, sy], [-sx, sy]])
        if self.shape == "cylinder":
            a = np.linspace(0, 2 * np.pi, 24, endpoint=False)
            return np.c_[self.radius * np.cos(a), self.radius * np.sin(a)]
        return model_footprint(self.model, self.scale)

    def footprint(self) -> NDArray[np.float64]:
        """``(K, 2)`` CCW polygon in the world frame."""
        return Pose2(self.x, self.y, self.yaw).transform_points(self.local_footprint())

    def z_range(self) -> tuple[float, float]:
        if self.shape == "box":
            return self.z, self.z + self.size[2]
        if self.shape == "cylinder":
            return self.z, self.z + self.height
        z0, z1 = model_z_range(self.model, self.scale)
        return self.z + z0, self.z + z1


@dataclass(frozen=True)
class WorldObject:
    """A classified object: ``label`` (the YAML ``class``), catalogue ``model``, pose (yaw radians)."""

    label: str
    model: str
    x: float
    y: float
    yaw: float = 0.0
    scale: float = 1.0
    color: RGB | None = None
    name: str = ""

    @property
    def pose(self) -> Pose2:
        return Pose2(self.x, self.y, self.yaw)

    def footprint(self) -> NDArray[np.float64]:
        """``(K, 2)`` CCW convex footprint in the world frame."""
        return self.pose.transform_points(model_footprint(self.model, self.scale))

    def z_range(self) -> tuple[float, float]:
        return model_z_range(self.model, self.scale)

    @property
    def legged(self) -> bool:
        return get_model(self.model).legged


@dataclass
class World:
    """A whole world. ``start`` is ``T_world_base`` at t = 0; routes are ``(N, 2)`` waypoint lists."""

    name: str = "world"
    walls: list[Wall] = field(default_factory=list)
    obstacles: list[Obstacle] = field(default_factory=list)
    objects: list[WorldObject] = field(default_factory=list)
    start: Pose2 = field(default_factory=Pose2)
    routes: dict[str, list[tuple[float, float]]] = field(default_factory=dict)
    floor_color: RGB = (0.72, 0.62, 0.5)
    wall_color: RGB = (0.92, 0.91, 0.88)
    description: str = ""
    seed: int | None = None
    source: str = ""

    def object_name(self, i: int) -> str:
        o = self.objects[i]
        return o.name or f"{o.label}_{i}"

    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` of the walls, obstacles and objects."""
        geoms = [w.polygon() for w in self.walls] + [Polygon(o.footprint()) for o in self.objects]
        geoms += [Polygon(o.footprint()) for o in self.obstacles]
        if not geoms:
            return (-1.0, -1.0, 1.0, 1.0)
        return tuple(unary_union(geoms).bounds)  # type: ignore[return-value]

    def route(self, name: str) -> NDArray[np.float64]:
        """``(N, 2)`` waypoints of a named route; ``WorldError`` naming the routes that exist."""
        if name not in self.routes:
            raise WorldError(f"{self.source or self.name}: no route {name!r} (routes: {', '.join(self.routes) or 'none'})")
        return np.asarray(self.routes[name], dtype=np.float64).reshape(-1, 2)

    def blocking_geometry(self) -> list[tuple[str, Any]]:
        """``[(entry name, shapely geometry)]`` of everything the robot cannot drive through
        (walls with floor-level openings cut out, obstacles and objects reaching below its height)."""
        out: list[tuple[str, Any]] = []
        for i, w in enumerate(self.walls):
            g = w.solid_polygon()
            if not g.is_empty:
                out.append((_wall_name(i, w), g))
        for i, o in enumerate(self.obstacles):
            if o.z_range()[0] < ROBOT_HEIGHT_M:
                out.append((_obstacle_name(i, o), Polygon(o.footprint())))
        for i, o in enumerate(self.objects):
            out.append((_object_name(i, o), Polygon(o.footprint())))
        return out


def _wall_name(i: int, w: Wall) -> str:
    return f"walls[{i}]" + (f" ({w.name!r})" if w.name else "")


def _obstacle_name(i: int, o: Obstacle) -> str:
    what = o.name or (o.model if o.shape == "model" else o.shape)
    return f"obstacles[{i}] ({what!r})"


def _object_name(i: int, o: WorldObject) -> str:
    return f"objects[{i}] (class {o.label!r}" + (f", {o.name!r})" if o.name else ")")


# ----------------------------------------------------------------------------------------------
# YAML → dataclasses
# ----------------------------------------------------------------------------------------------

_TOP_KEYS = {"name", "description", "seed", "floor_color", "wall_color", "walls", "obstacles", "objects", "start", "routes"}
_WALL_KEYS = {"from", "to", "thickness", "height", "openings", "color", "name"}
_OPENING_KEYS = {"start", "end", "bottom", "top", "kind"}
_OBSTACLE_KEYS = {"shape", "x", "y", "yaw", "size", "radius", "height", "z", "model", "scale", "color", "name"}
_OBJECT_KEYS = {"class", "model", "x", "y", "yaw", "scale", "color", "name"}
_START_KEYS = {"x", "y", "yaw"}


def _num(v: Any, where: str, key: str, *, positive: bool = False, nonneg: bool = False, limit: float | None = None) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
        raise WorldError(f"{where}: '{key}' must be a finite number, got {v!r}")
    f = float(v)
    if limit is not None and abs(f) > limit:
        what = f"coordinates are limited to ±{limit:g} m" if limit >= MAX_COORD_M else f"sizes are limited to {limit:g} m"
        raise WorldError(f"{where}: '{key}' is {v!r}; {what}")
    if positive and f <= 0:
        raise WorldError(f"{where}: '{key}' must be > 0, got {v!r}")
    if nonneg and f < 0:
        raise WorldError(f"{where}: '{key}' must be ≥ 0, got {v!r}")
    return f


def _xy(v: Any, where: str, key: str) -> tuple[float, float]:
    if not isinstance(v, (list, tuple)) or len(v) != 2:
        raise WorldError(f"{where}: '{key}' must be [x, y], got {v!r}")
    return (_num(v[0], where, key, limit=MAX_COORD_M), _num(v[1], where, key, limit=MAX_COORD_M))


def _mapping(v: Any, where: str, allowed: set[str], required: Sequence[str] = ()) -> dict:
    if not isinstance(v, dict):
        raise WorldError(f"{where}: expected a mapping, got {type(v).__name__}")
    unknown = sorted(set(map(str, v)) - allowed)
    if unknown:
        raise WorldError(f"{where}: unknown field(s) {', '.join(map(repr, unknown))} (allowed: {', '.join(sorted(allowed))})")
    for k in required:
        if k not in v:
            raise WorldError(f"{where}: missing field '{k}'")
    return v


def _color(v: Any, where: str, key: str = "color") -> RGB | None:
    if v is None:
        return None
    try:
        return parse_color(v)
    except ValueError as e:
        raise WorldError(f"{where}: '{key}': {e}") from None


def _list(v: Any, where: str) -> list:
    if v is None:
        return []
    if not isinstance(v, list):
        raise WorldError(f"{where}: expected a list, got {type(v).__name__}")
    return v


def _model_scale(model: str, v: Any, where: str) -> float:
    """A model's ``scale``: > 0, and the scaled model no larger than :data:`MAX_SIZE_M`."""
    f = _num(v, where, "scale", positive=True)
    fp = model_footprint(model, 1.0)
    extent = max(float(np.ptp(fp[:, 0])), float(np.ptp(fp[:, 1])), model_z_range(model, 1.0)[1], 1e-9)
    if f * extent > MAX_SIZE_M:
        raise WorldError(f"{where}: 'scale' {v!r} makes {model!r} {f * extent:.1f} m large; sizes are limited to {MAX_SIZE_M:g} m")
    return f


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


def world_from_dict(data: Any, source: str = "world") -> World:
    """Build (but do not validate the geometry of) a :class:`World` from parsed YAML."""
    d = _mapping(data, source, _TOP_KEYS, required=("walls", "start"))
    check_world_limits(d)
    walls = []
    for i, wd in enumerate(_list(d.get("walls"), f"{source}: walls")):
        where = f"walls[{i}]"
        wd = _mapping(wd, where, _WALL_KEYS, required=("from", "to"))
        openings = []
        for j, od in enumerate(_list(wd.get("openings"), f"{where}.openings")):
            ow = f"{where}.openings[{j}]"
            od = _mapping(od, ow, _OPENING_KEYS, required=("start", "end"))
            kind = od.get("kind", "passage")
            if kind not in ("door", "window", "passage"):
                raise WorldError(f"{ow}: 'kind' must be door, window or passage, got {kind!r}")
            default_bottom = 0.9 if kind == "window" else 0.0
            openings.append(
                Opening(
                    start=_num(od["start"], ow, "start", limit=2 * MAX_COORD_M),
                    end=_num(od["end"], ow, "end", limit=2 * MAX_COORD_M),
                    bottom=_num(od.get("bottom", default_bottom), ow, "bottom", nonneg=True, limit=MAX_SIZE_M),
                    top=_num(od.get("top", 2.1), ow, "top", positive=True, limit=MAX_SIZE_M),
                    kind=kind,
                )
            )
        walls.append(
            Wall(
                start=_xy(wd["from"], where, "from"),
                end=_xy(wd["to"], where, "to"),
                thickness=_num(wd.get("thickness", 0.15), where, "thickness", positive=True, limit=MAX_SIZE_M),
                height=_num(wd.get("height", 2.4), where, "height", positive=True, limit=MAX_SIZE_M),
                openings=tuple(openings),
                color=_color(wd.get("color"), where),
                name=str(wd.get("name", "")),
            )
        )
    obstacles = []
    for i, od in enumerate(_list(d.get("obstacles"), f"{source}: obstacles")):
        where = f"obstacles[{i}]"
        od = _mapping(od, where, _OBSTACLE_KEYS, required=("shape", "x", "y"))
        shape = od["shape"]
        if shape not in ("box", "cylinder", "model"):
            raise WorldError(f"{where}: 'shape' must be box, cylinder or model, got {shape!r}")
        kw: dict[str, Any] = {}
        if shape == "box":
            if "size" not in od:
                raise WorldError(f"{where}: missing field 'size' ([sx, sy, sz]) for a box")
            sz = od["size"]
            if not isinstance(sz, (list, tuple)) or len(sz) != 3:
                raise WorldError(f"{where}: 'size' must be [sx, sy, sz], got {sz!r}")
            kw["size"] = tuple(_num(v, where, "size", positive=True, limit=MAX_SIZE_M) for v in sz)
        elif shape == "cylinder":
            for k in ("radius", "height"):
                if k not in od:
                    raise WorldError(f"{where}: missing field '{k}' for a cylinder")
            kw["radius"] = _num(od["radius"], where, "radius", positive=True, limit=MAX_SIZE_M / 2)
            kw["height"] = _num(od["height"], where, "height", positive=True, limit=MAX_SIZE_M)
        else:
            if "model" not in od:
                raise WorldError(f"{where}: missing field 'model' for shape 'model'")
            model = od["model"]
            if model not in MODELS:
                raise WorldError(f"{where}: unknown model {model!r} (unclassified models: {', '.join(models_for_class(None))})")
            if MODELS[model].label is not None:
                raise WorldError(
                    f"{where}: model {model!r} is of class {MODELS[model].label!r}; put classified models under 'objects'"
                )
            kw["model"] = model
            kw["scale"] = _model_scale(model, od.get("scale", 1.0), where)
        obstacles.append(
            Obstacle(
                shape=shape,
                x=_num(od["x"], where, "x", limit=MAX_COORD_M),
                y=_num(od["y"], where, "y", limit=MAX_COORD_M),
                yaw=math.radians(_num(od.get("yaw", 0.0), where, "yaw")),
                z=_num(od.get("z", 0.0), where, "z", nonneg=True, limit=MAX_SIZE_M),
                color=_color(od.get("color"), where),
                name=str(od.get("name", "")),
                **kw,
            )
        )
    objects = []
    for i, od in enumerate(_list(d.get("objects"), f"{source}: objects")):
        where = f"objects[{i}]"
        if isinstance(od, dict) and "class" in od:
            where = f"objects[{i}] (class {od['class']!r})"
        od = _mapping(od, where, _OBJECT_KEYS, required=("class", "model", "x", "y"))
        label, model = od["class"], od["model"]
        if label not in CLASS_NAMES:
            raise WorldError(f"{where}: unknown class {label!r} (classes: {', '.join(CLASS_NAMES)})")
        if model not in MODELS:
            raise WorldError(f"{where}: unknown model {model!r} (models of class {label!r}: {', '.join(models_for_class(label))})")
        if MODELS[model].label != label:
            got = MODELS[model].label
            raise WorldError(
                f"{where}: model {model!r} is of class {got!r}, not {label!r} "
                f"(models of class {label!r}: {', '.join(models_for_class(label))})"
            )
        objects.append(
            WorldObject(
                label=label,
                model=model,
                x=_num(od["x"], where, "x", limit=MAX_COORD_M),
                y=_num(od["y"], where, "y", limit=MAX_COORD_M),
                yaw=math.radians(_num(od.get("yaw", 0.0), where, "yaw")),
                scale=_model_scale(model, od.get("scale", 1.0), where),
                color=_color(od.get("color"), where),
                name=str(od.get("name", "")),
            )
        )
    sd = _mapping(d["start"], "start", _START_KEYS, required=("x", "y"))
    start = Pose2(_num(sd["x"], "start", "x", limit=MAX_COORD_M), _num(sd["y"], "start", "y", limit=MAX_COORD_M), math.radians(_num(sd.get("yaw", 0.0), "start", "yaw")))
    routes: dict[str, list[tuple[float, float]]] = {}
    rd = d.get("routes") or {}
    if not isinstance(rd, dict):
        raise WorldError("routes: expected a mapping of name → waypoint list")
    for name, pts in rd.items():
        where = f"routes[{name!r}]"
        pts = _list(pts, where)
        if not pts:
            raise WorldError(f"{where}: a route needs at least one waypoint")
        routes[str(name)] = [_xy(p, f"{where}[{k}]", "waypoint") for k, p in enumerate(pts)]
    seed = d.get("seed")
    return World(
        name=str(d.get("name", Path(source).stem if source else "world")),
        walls=walls,
        obstacles=obstacles,
        objects=objects,
        start=start,
        routes=routes,
        floor_color=_color(d.get("floor_color"), source, "floor_color") or World.floor_color,
        wall_color=_color(d.get("wall_color"), source, "wall_color") or World.wall_color,
        description=str(d.get("description", "")),
        seed=int(seed) if isinstance(seed, int) and not isinstance(seed, bool) else None,
        source=source,
    )


def yaml_error_line(e: Exception) -> str:
    """A PyYAML error as one line: ``line L, column C: problem``."""
    mark = getattr(e, "problem_mark", None)
    problem = getattr(e, "problem", None) or str(e)
    where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
    return " ".join(f"{where}{problem}".split())


def load_world(path: str | Path, *, validate: bool = True) -> World:
    """Read and validate a world file. ``WorldError`` (a ``ValueError``) names the problem."""
    p = Path(path)
    try:
        size = p.stat().st_size
        if p.is_file() and size > MAX_FILE_BYTES:
            raise WorldError(f"{p}: {size / 2**20:.1f} MiB; world files are limited to {MAX_FILE_BYTES // 2**20} MiB")
        text = p.read_text(encoding="utf-8")
    except OSError as e:
        raise WorldError(f"cannot read world file {p}: {e.strerror or e}") from None
    except UnicodeDecodeError:
        raise WorldError(f"{p}: not a world file (binary data, not UTF-8 YAML text)") from None
    try:
        data = yaml.load(text, Loader=_YAML_LOADER)
    except yaml.YAMLError as e:
        raise WorldError(f"{p}: malformed YAML: {yaml_error_line(e)}") from None
    try:
        world = world_from_dict(data, source=str(p))
    except WorldError as e:
        raise WorldError(f"{p}: {e}") from None
    if validate:
        try:
            validate_world(world)
        except WorldError as e:
            raise WorldError(f"{p}: {e}") from None
    return world


# ----------------------------------------------------------------------------------------------
# dataclasses → YAML
# ----------------------------------------------------------------------------------------------


def _r(v: float, nd: int = 4) -> float:
    return float(round(float(v), nd)) + 0.0


def _c(c: RGB | None) -> list[float] | None:
    return None if c is None else [_r(v, 3) for v in c]


def world_to_dict(world: World) -> dict:
    """The YAML mapping of a world (yaws in degrees; default-valued optional fields omitted)."""
    d: dict[str, Any] = {"name": world.name}
    if world.description:
        d["description"] = world.description
    if world.seed is not None:
        d["seed"] = int(world.seed)
    d["floor_color"] = _c(world.floor_color)
    d["wall_color"] = _c(world.wall_color)
    d["start"] = {"x": _r(world.start.x), "y": _r(world.start.y), "yaw": _r(math.degrees(world.start.yaw), 2)}
    walls = []
    for w in world.walls:
        wd: dict[str, Any] = {}
        if w.name:
            wd["name"] = w.name
        wd.update({"from": [_r(w.start[0]), _r(w.start[1])], "to": [_r(w.end[0]), _r(w.end[1])],
                   "thickness": _r(w.thickness), "height": _r(w.height)})
        if w.openings:
            wd["openings"] = [
                {"kind": o.kind, "start": _r(o.start), "end": _r(o.end), "bottom": _r(o.bottom), "top": _r(o.top)}
                for o in w.openings
            ]
        if w.color is not None:
            wd["color"] = _c(w.color)
        walls.append(wd)
    d["walls"] = walls
    obs = []
    for o in world.obstacles:
        od: dict[str, Any] = {}
        if o.name:
            od["name"] = o.name
        od["shape"] = o.shape
        if o.shape == "model":
            od["model"] = o.model
        od.update({"x": _r(o.x), "y": _r(o.y), "yaw": _r(math.degrees(o.yaw), 2)})
        if o.shape == "box":
            od["size"] = [_r(v) for v in o.size]
        elif o.shape == "cylinder":
            od["radius"], od["height"] = _r(o.radius), _r(o.height)
        elif o.scale != 1.0:
            od["scale"] = _r(o.scale)
        if o.z:
            od["z"] = _r(o.z)
        if o.color is not None:
            od["color"] = _c(o.color)
        obs.append(od)
    d["obstacles"] = obs
    objs = []
    for o in world.objects:
        od = {}
        if o.name:
            od["name"] = o.name
        od.update({"class": o.label, "model": o.model, "x": _r(o.x), "y": _r(o.y), "yaw": _r(math.degrees(o.yaw), 2)})
        if o.scale != 1.0:
            od["scale"] = _r(o.scale)
        if o.color is not None:
            od["color"] = _c(o.color)
        objs.append(od)
    d["objects"] = objs
    d["routes"] = {name: [[_r(x, 3), _r(y, 3)] for x, y in pts] for name, pts in world.routes.items()}
    return d


class _FlowListDumper(yaml.SafeDumper):
    pass


def _repr_list(dumper: yaml.SafeDumper, data: list) -> Any:
    flow = all(isinstance(v, (int, float)) for v in data) or all(isinstance(v, list) and len(v) <= 3 for v in data) and len(data) <= 3
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flow)


def _repr_dict(dumper: yaml.SafeDumper, data: dict) -> Any:
    flow = bool(data) and all(isinstance(v, (int, float, str)) for v in data.values()) and "from" not in data and len(data) <= 8
    return dumper.represent_mapping("tag:yaml.org,2002:map", data.items(), flow_style=flow)


_FlowListDumper.add_representer(list, _repr_list)
_FlowListDumper.add_representer(dict, _repr_dict)


def dump_world(world: World, path: str | Path | None = None) -> str:
    """The world as YAML text; written atomically to ``path`` when given."""
    header = f"# OCSLAM world '{world.name}' (format: docs/world-format.md). Yaws in degrees.\n"
    text = header + yaml.dump(world_to_dict(world), Dumper=_FlowListDumper, sort_keys=False, width=120, allow_unicode=True)
    if path is not None:
        atomic_write_text(path, text)
    return text


# ----------------------------------------------------------------------------------------------
# Validation
# ----------------------------------------------------------------------------------------------


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
        name = _wall_name(i, w)
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
            raise WorldError(f"{_obstacle_name(i, o)}: ({o.x}, {o.y}) is beyond ±{MAX_COORD_M:g} m")
        if o.shape == "model" and o.model not in MODELS:
            raise WorldError(f"{_obstacle_name(i, o)}: unknown model {o.model!r}")
    for i, o in enumerate(world.objects):
        name = _object_name(i, o)
        if max(abs(o.x), abs(o.y)) > MAX_COORD_M:
            raise WorldError(f"{name}: ({o.x}, {o.y}) is beyond ±{MAX_COORD_M:g} m")
        if o.label not in CLASS_NAMES:
            raise WorldError(f"{name}: unknown class {o.label!r}")
        if o.model not in MODELS:
            raise WorldError(f"{name}: unknown model {o.model!r}")
        if MODELS[o.model].label != o.label:
            raise WorldError(f"{name}: model {o.model!r} is of class {MODELS[o.model].label!r}")
    wall_names = [_wall_name(i, w) for i, w in enumerate(world.walls)]
    wall_geoms = [w.solid_polygon() for w in world.walls]
    wall_idx = [k for k, g in enumerate(wall_geoms) if not g.is_empty]
    # obstacles first, then objects, each against the walls and everything placed before it
    names = [_obstacle_name(i, o) for i, o in enumerate(world.obstacles)] + [_object_name(i, o) for i, o in enumerate(world.objects)]
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
        raise WorldError(f"{_object_name(i, o)}: at ({o.x:.3f}, {o.y:.3f}) is outside every room ({why})")
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


# ----------------------------------------------------------------------------------------------
# Random worlds
# ----------------------------------------------------------------------------------------------

_FLOORS = [(0.72, 0.62, 0.5), (0.55, 0.42, 0.3), (0.8, 0.78, 0.74), (0.45, 0.45, 0.47), (0.82, 0.7, 0.55), (0.6, 0.56, 0.5)]
_WALLS = [(0.92, 0.91, 0.88), (0.86, 0.88, 0.9), (0.93, 0.88, 0.8), (0.8, 0.85, 0.8), (0.95, 0.95, 0.95), (0.85, 0.8, 0.78)]


@dataclass
class _Room:
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


def _split_rooms(rng: np.random.Generator, W: float, H: float, n_target: int) -> list[_Room]:
    rooms = [_Room(0.0, 0.0, W, H)]
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
            a, b = _Room(r.x0, r.y0, r.x0 + cut, r.y1), _Room(r.x0 + cut, r.y0, r.x1, r.y1)
        else:
            a, b = _Room(r.x0, r.y0, r.x1, r.y0 + cut), _Room(r.x0, r.y0 + cut, r.x1, r.y1)
        rooms[0:1] = [a, b]
    return rooms


def _shared_edge(a: _Room, b: _Room) -> tuple[str, float, float, float] | None:
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


def _grid_path(
    free: NDArray[np.bool_], a: tuple[int, int], b: tuple[int, int], cost: NDArray[np.float64] | None = None
) -> list[tuple[int, int]] | None:
    """8-connected A* on a boolean grid (row, col); ``cost`` (≥ 1) multiplies the step length."""
    H, W = free.shape
    if not (free[a] and free[b]):
        return None
    openq = [(0.0, a)]
    came: dict[tuple[int, int], tuple[int, int]] = {}
    g = {a: 0.0}
    steps = [(-1, 0, 1.0), (1, 0, 1.0), (0, -1, 1.0), (0, 1, 1.0), (-1, -1, 1.414), (-1, 1, 1.414), (1, -1, 1.414), (1, 1, 1.414)]
    while openq:
        _, cur = heapq.heappop(openq)
        if cur == b:
            path = [cur]
            while cur in came:
                cur = came[cur]
                path.append(cur)
            return path[::-1]
        for dr, dc, step in steps:
            nr, nc = cur[0] + dr, cur[1] + dc
            if 0 <= nr < H and 0 <= nc < W and free[nr, nc]:
                if dr and dc and not (free[cur[0] + dr, cur[1]] and free[cur[0], cur[1] + dc]):
                    continue
                ng = g[cur] + step * (1.0 if cost is None else float(cost[nr, nc]))
                if ng < g.get((nr, nc), 1e18):
                    g[(nr, nc)] = ng
                    came[(nr, nc)] = cur
                    h = math.hypot(nr - b[0], nc - b[1])
                    heapq.heappush(openq, (ng + h, (nr, nc)))
    return None


class _Planner:
    """Grid planner over the world's blocking geometry: cells within ``clearance`` of anything are
    forbidden, cells within ``preferred`` cost more, so routes keep well away from obstacles where the
    space allows and squeeze through doorways where it does not."""

    def __init__(self, world: World, clearance: float, preferred: float = 0.35, res: float = 0.05) -> None:
        xmin, ymin, xmax, ymax = world.bounds()
        self.res, self.x0, self.y0 = res, xmin, ymin
        self.W = int(math.ceil((xmax - xmin) / res)) + 1
        self.H = int(math.ceil((ymax - ymin) / res)) + 1
        self.blocking = unary_union([g for _, g in world.blocking_geometry()])
        self.clearance, self.preferred = clearance, preferred
        jj, ii = np.meshgrid(np.arange(self.W), np.arange(self.H))
        pts = np.c_[xmin + (jj.ravel() + 0.5) * res, ymin + (ii.ravel() + 0.5) * res]
        self.dist = shapely.distance(self.blocking, shapely.points(pts)).reshape(self.H, self.W)
        # a margin of one cell so straight lines between neighbouring cell centres keep the clearance
        self.free = self.dist >= clearance + res * 0.75
        self.cost = np.where(self.dist >= preferred, 1.0, 4.0)

    def cell(self, x: float, y: float) -> tuple[int, int]:
        return (int((y - self.y0) / self.res), int((x - self.x0) / self.res))

    def point(self, c: tuple[int, int]) -> tuple[float, float]:
        return (self.x0 + (c[1] + 0.5) * self.res, self.y0 + (c[0] + 0.5) * self.res)

    def clear(self, a: tuple[float, float], b: tuple[float, float]) -> bool:
        """The segment keeps ``preferred`` clearance, or at least as much as its end points have."""
        need = min(self.preferred, self.blocking.distance(Point(a)), self.blocking.distance(Point(b)))
        need = max(need - 0.01, self.clearance + 1e-3)
        seg = LineString([a, b]) if a != b else Point(a)
        return self.blocking.distance(seg) >= need

    def nearest_free(self, x: float, y: float, max_r: float = 1.5) -> tuple[int, int] | None:
        r0, c0 = self.cell(x, y)
        k = int(max_r / self.res)
        rs = slice(max(0, r0 - k), min(self.H, r0 + k + 1))
        cs = slice(max(0, c0 - k), min(self.W, c0 + k + 1))
        sub = self.free[rs, cs] & (self.dist[rs, cs] >= min(self.preferred, self.clearance + 0.1))
        if not sub.any():
            sub = self.free[rs, cs]
            if not sub.any():
                return None
        ii, jj = np.nonzero(sub)
        ii, jj = ii + rs.start, jj + cs.start
        k = int(np.argmin((ii - r0) ** 2 + (jj - c0) ** 2))
        return (int(ii[k]), int(jj[k]))

    def plan(self, a: tuple[float, float], b: tuple[float, float]) -> list[tuple[float, float]] | None:
        ca, cb = self.nearest_free(*a), self.nearest_free(*b)
        if ca is None or cb is None:
            return None
        cells = _grid_path(self.free, ca, cb, self.cost)
        if cells is None:
            return None
        pts = [self.point(c) for c in cells]
        # string pulling: keep the farthest point reachable in a straight, clear line
        out = [pts[0]]
        i = 0
        while i < len(pts) - 1:
            j = len(pts) - 1
            while j > i + 1 and not self.clear(pts[i], pts[j]):
                j -= 1
            out.append(pts[j])
            i = j
        return out


def random_world(seed: int, *, n_rooms: int | None = None, extra_objects: int | None = None, family: str = "rooms") -> World:
    """A randomized, valid apartment: rooms with doorways, every class present, colours varied.

    The world is a rectangle of 7–11 × 5–8 m split into 3–5 rooms joined by doorways; outer walls
    carry windows and closed doors (class ``door``); objects stand along walls and in the open, with
    room for the robot to pass. The ``tour`` route starts at the robot and visits every room (segments
    keep the robot radius + margin from everything). Deterministic for a seed.
    ``family`` other than ``rooms`` (``corridor``, ``lshape``, ``openplan``) builds that layout family
    instead (:mod:`app.world_layouts`).
    """
    if family != "rooms":
        from app.world_layouts import generate

        return generate(family, seed)
    rng = np.random.default_rng(seed)
    for attempt in range(40):
        w = _try_random_world(rng, seed, n_rooms, extra_objects)
        if w is not None:
            try:
                validate_world(w)
            except WorldError:
                continue
            return w
    raise WorldError(f"random_world(seed={seed}): could not build a valid world in 40 attempts")


def _try_random_world(rng: np.random.Generator, seed: int, n_rooms: int | None, extra_objects: int | None) -> World | None:
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
    for i, j, e in doorways:
        kind, c, lo, hi = e
        width = round(float(rng.uniform(0.9, 1.1)), 2)
        s0 = float(rng.uniform(0.35, (hi - lo) - width - 0.35))
        interior_segments.setdefault(e, []).append(Opening(s0, s0 + width, 0.0, 2.1, "passage"))
        mid = lo + s0 + width / 2
        doorway_points.append((c, mid) if kind == "v" else (mid, c))
    interior_doors: list[tuple[tuple, float]] = []  # (edge, s_mid): closed doors between rooms
    for i, j, e in edges:
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
        floor_color=_FLOORS[int(rng.integers(len(_FLOORS)))],
        wall_color=_WALLS[int(rng.integers(len(_WALLS)))],
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
        color = _pick_color(rng, "door")
        objects.append(WorldObject("door", "door", px, py, yaw, 1.0, color))
        keepout.append(Point(px, py).buffer(0.6))

    for e, s_mid in interior_doors:
        kind, c, lo, hi = e
        px, py = (c, lo + s_mid) if kind == "v" else (lo + s_mid, c)
        yaw = 0.0 if kind == "v" else math.pi / 2  # the door's x axis crosses the wall
        objects.append(WorldObject("door", "door", px, py, yaw, 1.0, _pick_color(rng, "door")))
        keepout.append(Point(px, py).buffer(0.6))

    def fits(fp: Polygon, gap: float) -> bool:
        if fp.buffer(0.02).intersects(wall_solid):
            return False
        if any(fp.intersects(k) for k in keepout):
            return False
        if any(fp.distance(p) < gap for p in placed):
            return False
        return any(fp.within(r.poly.buffer(-0.08)) for r in rooms)

    def place(label: str | None, model: str, room: _Room, against_wall: bool, gap: float = 0.5) -> bool:
        spec = get_model(model)
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
                color = _pick_color(rng, model)
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
    planner = _Planner(world, ROBOT_RADIUS_M + ROUTE_MARGIN_M + 0.02, preferred=0.35)
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


def _room_viewpoints(planner: "_Planner", room: _Room, cur: tuple[float, float]) -> list[tuple[float, float]]:
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


def _pick_color(rng: np.random.Generator, model: str) -> RGB | None:
    from app.world_models import jitter_color

    spec = get_model(model)
    if not spec.palette:
        return None
    base = spec.palette[int(rng.integers(len(spec.palette)))]
    c = jitter_color(base, rng, 0.08)
    return (round(c[0], 3), round(c[1], 3), round(c[2], 3))


def class_counts(world: World) -> dict[str, int]:
    """Number of objects per class (all 11 classes, zeros included)."""
    out = {c: 0 for c in CLASS_NAMES}
    for o in world.objects:
        out[o.label] += 1
    return out


def iter_entries(world: World) -> Iterable[tuple[str, Any]]:
    """``(entry name, dataclass)`` for walls, obstacles and objects (for messages and UIs)."""
    for i, w in enumerate(world.walls):
        yield _wall_name(i, w), w
    for i, o in enumerate(world.obstacles):
        yield _obstacle_name(i, o), o
    for i, ob in enumerate(world.objects):
        yield _object_name(i, ob), ob


def with_objects(world: World, objects: list[WorldObject]) -> World:
    """A copy of ``world`` with another object list."""
    return replace(world, objects=list(objects))
