"""World files: YAML → dataclasses and back (the format of ``docs/world-format.md``).

**In YAML, yaws are in degrees**; in the dataclasses (:mod:`app.world.types`) they are radians.
:func:`load_world` reads, parses and validates (:mod:`app.world.validation`) a file; a problem is a
:class:`~app.world.types.WorldError` naming the offending entry.

Example:
    >>> world = load_world("assets/worlds/apartment.yaml")      # validated; WorldError otherwise
    >>> [o.label for o in world.objects][:3]
    ['ball', 'dog', 'gnome']
    >>> dump_world(world, "/tmp/apartment.yaml")                 # the same world, back as YAML
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from app.config import atomic_write_text
from app.ocslam.messages import CLASS_NAMES
from app.ocslam.se2 import Pose2
from app.world.models.catalogue import MODELS, models_for_class
from app.world.models.colors import parse_color
from app.world.models.geometry import model_footprint, model_z_range
from app.world.types import RGB, Obstacle, Opening, Wall, World, WorldError, WorldObject
from app.world.validation import (
    MAX_COORD_M,
    MAX_FILE_BYTES,
    MAX_SIZE_M,
    check_world_limits,
    validate_world,
)

__all__ = ["load_world", "dump_world", "world_from_dict", "world_to_dict", "yaml_error_line"]

#: libyaml's safe loader where PyYAML has it (several times faster), else the pure-Python one
_YAML_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


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
