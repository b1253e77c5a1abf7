"""World dataclasses: walls with openings, obstacles, classified objects, the world (no pybullet here).

A world is walls (segments with thickness, height and openings for doors and windows), static
obstacles (boxes, cylinders or unclassified models), classified objects (``class``, ``model``,
``x``, ``y``, ``yaw``, optional ``scale`` and ``color``), the robot's start pose and named routes.
Frames: the world frame is ENU (x east, y north, z up), metres; yaws here are radians (degrees in
YAML, :mod:`app.world.format`). Validation: :mod:`app.world.validation`.

Example:
    >>> w = World(walls=[Wall((0.0, 0.0), (4.0, 0.0))])
    >>> w.walls[0].length
    4.0
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from shapely.geometry import Polygon
from shapely.ops import unary_union

from app.ocslam.messages import CLASS_NAMES
from app.ocslam.se2 import Pose2
from app.world.models.catalogue import get_model
from app.world.models.geometry import model_footprint, model_z_range

__all__ = [
    "WorldError",
    "Opening",
    "Wall",
    "Obstacle",
    "WorldObject",
    "World",
    "class_counts",
    "iter_entries",
    "with_objects",
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
        b = np.array([g.bounds for g in geoms if not g.is_empty], dtype=np.float64).reshape(-1, 4)
        if not len(b):
            return (-1.0, -1.0, 1.0, 1.0)
        # the union's bounds are the extremes of the parts' (no union needed)
        return (float(b[:, 0].min()), float(b[:, 1].min()), float(b[:, 2].max()), float(b[:, 3].max()))

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
                out.append((wall_entry_name(i, w), g))
        for i, o in enumerate(self.obstacles):
            if o.z_range()[0] < ROBOT_HEIGHT_M:
                out.append((obstacle_entry_name(i, o), Polygon(o.footprint())))
        for i, o in enumerate(self.objects):
            out.append((object_entry_name(i, o), Polygon(o.footprint())))
        return out


def wall_entry_name(i: int, w: Wall) -> str:
    return f"walls[{i}]" + (f" ({w.name!r})" if w.name else "")


def obstacle_entry_name(i: int, o: Obstacle) -> str:
    what = o.name or (o.model if o.shape == "model" else o.shape)
    return f"obstacles[{i}] ({what!r})"


def object_entry_name(i: int, o: WorldObject) -> str:
    return f"objects[{i}] (class {o.label!r}" + (f", {o.name!r})" if o.name else ")")


def class_counts(world: World) -> dict[str, int]:
    """Number of objects per class (all 11 classes, zeros included)."""
    out = {c: 0 for c in CLASS_NAMES}
    for o in world.objects:
        out[o.label] += 1
    return out


def iter_entries(world: World) -> Iterable[tuple[str, Any]]:
    """``(entry name, dataclass)`` for walls, obstacles and objects (for messages and UIs)."""
    for i, w in enumerate(world.walls):
        yield wall_entry_name(i, w), w
    for i, o in enumerate(world.obstacles):
        yield obstacle_entry_name(i, o), o
    for i, ob in enumerate(world.objects):
        yield object_entry_name(i, ob), ob


def with_objects(world: World, objects: list[WorldObject]) -> World:
    """A copy of ``world`` with another object list."""
    return replace(world, objects=list(objects))
