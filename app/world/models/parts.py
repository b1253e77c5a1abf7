"""Model parts: the primitives (boxes, cylinders, spheres, capsules, ellipsoids, meshes) models are made of.

A model is a list of :class:`Part` in the model's own frame: origin at the centre of its footprint
on the floor, +x its front, +y its left, z up, metres at ``scale = 1``. :class:`ModelSpec` is one
catalogue entry (:mod:`app.world.models.catalogue`).

Example:
    >>> box((0.1, 0.1, 0.7), (0.45, 0.85, 0.35), "legs").shape
    'box'
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from app.config import ASSETS

__all__ = ["Part", "ModelSpec", "box", "cyl", "caps", "sph", "mesh", "ell", "hex_rgb", "COLLISION_ONLY", "MESH_DIR", "RGB"]

RGB = tuple[float, float, float]
#: role of a part that only collides (no visual): e.g. the soccer ball's exact sphere under its mesh
COLLISION_ONLY = "__collision_only__"
MESH_DIR = ASSETS / "meshes" / "objects"
PI = math.pi


# ----------------------------------------------------------------------------------------------
# Parts and models
# ----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Part:
    """One rigid piece of a model, in the model frame.

    ``shape``: ``box`` (dims = full extents sx, sy, sz), ``cylinder``/``capsule`` (dims = radius,
    length along the part's z; a capsule's length excludes its caps, as in pybullet and trimesh),
    ``sphere`` (dims = radius,), ``mesh`` (dims = per-axis scale of the mesh file).
    ``mesh``: ``"name.obj"`` in :data:`MESH_DIR` or ``"pybullet_data:path.obj"``.
    ``collision``: ``"auto"`` (the primitive itself, or the convex hull of the mesh), ``"box"``
    (a box of extents ``dims``: for a scaled unit-cube mesh), ``"none"``, or a mesh reference.
    """

    shape: str
    dims: tuple[float, ...]
    pos: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    role: str = "body"
    mesh: str = ""
    collision: str = "auto"


def box(size: Sequence[float], pos: Sequence[float], role: str = "body", rpy: Sequence[float] = (0, 0, 0)) -> Part:
    return Part("box", tuple(map(float, size)), tuple(map(float, pos)), tuple(map(float, rpy)), role)  # type: ignore[arg-type]


def cyl(r: float, length: float, pos: Sequence[float], role: str = "body", rpy: Sequence[float] = (0, 0, 0)) -> Part:
    return Part("cylinder", (float(r), float(length)), tuple(map(float, pos)), tuple(map(float, rpy)), role)  # type: ignore[arg-type]


def caps(r: float, length: float, pos: Sequence[float], role: str = "body", rpy: Sequence[float] = (0, 0, 0)) -> Part:
    return Part("capsule", (float(r), float(length)), tuple(map(float, pos)), tuple(map(float, rpy)), role)  # type: ignore[arg-type]


def sph(r: float, pos: Sequence[float], role: str = "body") -> Part:
    return Part("sphere", (float(r),), tuple(map(float, pos)), (0.0, 0.0, 0.0), role)  # type: ignore[arg-type]


def mesh(
    name: str,
    scale: Sequence[float],
    pos: Sequence[float],
    role: str = "body",
    rpy: Sequence[float] = (0, 0, 0),
    collision: str = "auto",
) -> Part:
    return Part("mesh", tuple(map(float, scale)), tuple(map(float, pos)), tuple(map(float, rpy)), role, name, collision)  # type: ignore[arg-type]


def ell(radii: Sequence[float], pos: Sequence[float], role: str = "body", rpy: Sequence[float] = (0, 0, 0)) -> Part:
    """An ellipsoid with semi-axes ``radii`` (the unit-sphere mesh, scaled)."""
    return mesh("ellipsoid.obj", radii, pos, role, rpy)


@dataclass(frozen=True)
class ModelSpec:
    """A catalogue entry.

    ``label`` is the detector class (``None``: an unclassified obstacle). ``colors`` maps each part
    role to its default RGB in [0, 1]; a world object's ``color`` replaces the ``primary`` role and
    ``palette`` lists plausible primary colours for random worlds. ``legged``: the LIDAR plane
    (0.173 m) cuts the model in several separate legs.
    """

    name: str
    label: str | None
    parts: tuple[Part, ...]
    colors: dict[str, RGB]
    primary: str
    palette: tuple[RGB, ...] = ()
    legged: bool = False
    description: str = ""
    #: models that sit in a wall opening (doors): validation lets them fill a floor-level opening
    in_wall: bool = False
    tags: tuple[str, ...] = field(default_factory=tuple)


def hex_rgb(h: str) -> RGB:
    h = h.lstrip("#")
    return (int(h[0:2], 16) / 255.0, int(h[2:4], 16) / 255.0, int(h[4:6], 16) / 255.0)
