"""The object model catalogue: every model a world file may name, as coloured parts.

A model is a list of :class:`Part` (boxes, cylinders, spheres, capsules and small meshes) in the
model's own frame: origin at the centre of its footprint on the floor, +x its front, +y its left,
z up, metres at ``scale = 1``. The same parts build

- the pybullet bodies of the simulator (one static body per part, coloured per part, with collision
  shapes, so LIDAR rays and the robot meet the legs of a table, not its bounding box),
- the model's footprint polygon, height range and trimesh visual (for validation, ground truth and
  the web view), without pybullet.

Real meshes come from ``pybullet_data`` where one fits (rubber duck, soccer ball, wooden table top);
the rest is built from primitives and the unit meshes written by ``scripts/make_object_meshes.py``
(``assets/meshes/objects``). Sizes follow the paper's apartment (spec §5).

Example:
    >>> spec = get_model("dog")
    >>> spec.label, spec.legged
    ('dog', True)
    >>> model_footprint("dog").shape          # (K, 2) convex polygon in the model frame, CCW
"""

from __future__ import annotations

import colorsys
import math
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Callable, Iterable, Sequence

import numpy as np
from numpy.typing import NDArray

from app.config import ASSETS
from app.ocslam.messages import CLASS_NAMES

__all__ = [
    "Part",
    "ModelSpec",
    "MODELS",
    "MESH_DIR",
    "get_model",
    "models_for_class",
    "model_footprint",
    "model_z_range",
    "model_parts_trimesh",
    "model_trimesh",
    "resolve_colors",
    "jitter_color",
    "parse_color",
    "build_model_pybullet",
    "mesh_path",
    "world_visual_meshes",
]

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


def _rgb(h: str) -> RGB:
    h = h.lstrip("#")
    return (int(h[0:2], 16) / 255.0, int(h[2:4], 16) / 255.0, int(h[4:6], 16) / 255.0)


# -- classified models -------------------------------------------------------------------------


def _soccer_ball() -> ModelSpec:
    r = 0.1125  # FIFA size 5
    p = mesh("pybullet_data:soccerball.obj", (2 * r,) * 3, (0, 0, r), "ball", collision="none")
    return ModelSpec(
        "soccer_ball",
        "ball",
        (p, Part("sphere", (r,), (0.0, 0.0, r), (0.0, 0.0, 0.0), COLLISION_ONLY)),
        {"ball": (1.0, 1.0, 1.0)},
        "ball",
        palette=((1.0, 1.0, 1.0), (1.0, 0.95, 0.75), (0.85, 0.92, 1.0), (1.0, 0.85, 0.85)),
        description="FIFA size-5 soccer ball (pybullet_data mesh, texture tinted by the colour)",
    )


def _play_ball() -> ModelSpec:
    r = 0.11
    parts = (
        sph(r, (0, 0, r), "ball"),
        cyl(r + 0.0015, 0.035, (0, 0, r), "band"),
        cyl(r + 0.0015, 0.035, (0, 0, r), "band2", rpy=(PI / 2, 0, 0)),
    )
    return ModelSpec(
        "play_ball",
        "ball",
        parts,
        {"ball": _rgb("d62828"), "band": _rgb("f7d716"), "band2": _rgb("1d6fd6")},
        "ball",
        palette=(_rgb("d62828"), _rgb("2a9d8f"), _rgb("f77f00"), _rgb("6a4c93"), _rgb("e9c46a")),
        description="rubber play ball with two coloured bands",
    )


def _dog() -> ModelSpec:
    parts: list[Part] = []
    for x in (0.22, -0.22):
        for y in (0.085, -0.085):
            parts.append(cyl(0.05, 0.34, (x, y, 0.19), "fur"))
            parts.append(ell((0.065, 0.05, 0.025), (x + 0.02, y, 0.025), "paws"))
    parts += [
        ell((0.32, 0.13, 0.14), (0.0, 0.0, 0.44), "fur"),
        ell((0.14, 0.12, 0.15), (0.19, 0.0, 0.45), "chest"),
        cyl(0.07, 0.2, (0.31, 0.0, 0.55), "fur", rpy=(0, 0.62, 0)),
        ell((0.12, 0.085, 0.09), (0.39, 0.0, 0.65), "fur"),
        ell((0.08, 0.045, 0.045), (0.49, 0.0, 0.62), "muzzle"),
        sph(0.02, (0.565, 0.0, 0.635), "nose"),
        sph(0.014, (0.47, 0.042, 0.68), "nose"),
        sph(0.014, (0.47, -0.042, 0.68), "nose"),
        ell((0.035, 0.015, 0.075), (0.36, 0.085, 0.63), "ears", rpy=(0.25, 0, 0)),
        ell((0.035, 0.015, 0.075), (0.36, -0.085, 0.63), "ears", rpy=(-0.25, 0, 0)),
        caps(0.025, 0.17, (-0.36, 0.0, 0.53), "fur", rpy=(0, -0.75, 0)),
    ]
    return ModelSpec(
        "dog",
        "dog",
        tuple(parts),
        {
            "fur": _rgb("8b5a2b"),
            "chest": _rgb("c8a27a"),
            "paws": _rgb("d9c3a5"),
            "muzzle": _rgb("c8a27a"),
            "nose": _rgb("141414"),
            "ears": _rgb("4a2e17"),
        },
        "fur",
        palette=(_rgb("8b5a2b"), _rgb("2b2b2b"), _rgb("d4a55a"), _rgb("e8e0d0"), _rgb("6b4a32"), _rgb("a0522d")),
        legged=True,
        description="a medium dog (≈1.0 × 0.27 × 0.75 m); legs r 0.05 m, front and rear pairs 0.44 m apart",
    )


def _gnome() -> ModelSpec:
    parts = (
        ell((0.07, 0.045, 0.035), (0.03, 0.055, 0.035), "boots"),
        ell((0.07, 0.045, 0.035), (0.03, -0.055, 0.035), "boots"),
        cyl(0.09, 0.12, (0.0, 0.0, 0.12), "pants"),
        mesh("frustum.obj", (0.12, 0.11, 0.30), (0.0, 0.0, 0.31), "coat"),
        cyl(0.106, 0.04, (0.0, 0.0, 0.33), "belt"),
        caps(0.034, 0.15, (0.02, 0.11, 0.37), "coat", rpy=(0.35, 0.3, 0)),
        caps(0.034, 0.15, (0.02, -0.11, 0.37), "coat", rpy=(-0.35, 0.3, 0)),
        sph(0.035, (0.065, 0.1, 0.29), "skin"),
        sph(0.035, (0.065, -0.1, 0.29), "skin"),
        mesh("cone.obj", (0.085, 0.075, 0.22), (0.05, 0.0, 0.49), "beard", rpy=(PI, 0, 0)),
        sph(0.075, (0.0, 0.0, 0.575), "skin"),
        sph(0.024, (0.075, 0.0, 0.57), "nose"),
        mesh("cone.obj", (0.1, 0.1, 0.32), (-0.01, 0.0, 0.78), "hat", rpy=(0, -0.12, 0)),
    )
    return ModelSpec(
        "gnome",
        "gnome",
        parts,
        {
            "boots": _rgb("3b2314"),
            "pants": _rgb("5b7a3a"),
            "coat": _rgb("2456a4"),
            "belt": _rgb("1a1a1a"),
            "skin": _rgb("f1c9a5"),
            "nose": _rgb("e8967a"),
            "beard": _rgb("f2f2f2"),
            "hat": _rgb("c8102e"),
        },
        "hat",
        palette=(_rgb("c8102e"), _rgb("e63946"), _rgb("2a9d8f"), _rgb("1d3557"), _rgb("8338ec")),
        description="garden gnome (≈0.27 × 0.24 m footprint, 0.94 m tall)",
    )


def _table() -> ModelSpec:
    # Webots 'Table' convention: 1.0 m along x, 1.8 m along y, 0.74 m high, 0.1 m square legs.
    wood = "pybullet_data:table/table.obj"
    parts = [mesh(wood, (1.0, 1.8, 0.04), (0.0, 0.0, 0.72), "top", collision="box")]
    for x in (0.45, -0.45):
        for y in (0.85, -0.85):
            parts.append(mesh(wood, (0.1, 0.1, 0.70), (x, y, 0.35), "legs", collision="box"))
    return ModelSpec(
        "table",
        "table",
        tuple(parts),
        {"top": (1.0, 1.0, 1.0), "legs": (0.92, 0.92, 0.92)},
        "top",
        palette=((1.0, 1.0, 1.0), (0.75, 0.6, 0.5), (0.55, 0.4, 0.32), (0.9, 0.85, 0.8)),
        legged=True,
        description="dining table 1.0 × 1.8 × 0.74 m with 4 legs (pybullet_data wood texture, tinted by the colour)",
    )


def _round_table() -> ModelSpec:
    parts = (
        cyl(0.5, 0.035, (0, 0, 0.7325), "top"),
        cyl(0.04, 0.68, (0, 0, 0.37), "legs"),
        cyl(0.25, 0.03, (0, 0, 0.015), "legs"),
    )
    return ModelSpec(
        "round_table",
        "table",
        parts,
        {"top": _rgb("b08d6a"), "legs": _rgb("3a3a3a")},
        "top",
        palette=(_rgb("b08d6a"), _rgb("f0f0f0"), _rgb("6b4a32"), _rgb("d8c3a5")),
        description="round pedestal table, Ø 1.0 m, 0.75 m high (one central column at LIDAR height)",
    )


def _dining_chair() -> ModelSpec:
    parts = []
    for x in (0.19, -0.19):
        for y in (0.19, -0.19):
            parts.append(box((0.035, 0.035, 0.45), (x, y, 0.225), "legs"))
    parts += [
        box((0.44, 0.44, 0.04), (0.0, 0.0, 0.47), "seat"),
        box((0.035, 0.035, 0.45), (-0.19, 0.19, 0.715), "legs"),
        box((0.035, 0.035, 0.45), (-0.19, -0.19, 0.715), "legs"),
        box((0.03, 0.40, 0.22), (-0.19, 0.0, 0.82), "seat"),
    ]
    return ModelSpec(
        "dining_chair",
        "chair",
        tuple(parts),
        {"legs": _rgb("6b4a32"), "seat": _rgb("a0522d")},
        "seat",
        palette=(_rgb("a0522d"), _rgb("2f4f4f"), _rgb("d2b48c"), _rgb("8b0000"), _rgb("f5f5f5"), _rgb("556b2f")),
        legged=True,
        description="dining chair, seat 0.44 × 0.44 m at 0.47 m, back 0.94 m; four legs",
    )


def _sofa(name: str, width: float, n: int, description: str) -> ModelSpec:
    d = 1.0
    parts: list[Part] = []
    for x in (d / 2 - 0.06, -d / 2 + 0.06):
        for y in (width / 2 - 0.06, -width / 2 + 0.06):
            parts.append(cyl(0.03, 0.1, (x, y, 0.05), "feet"))
    parts += [
        box((d, width, 0.25), (0.0, 0.0, 0.225), "fabric"),
        mesh("rounded_box.obj", (0.22, width, 0.45), (-d / 2 + 0.11, 0.0, 0.575), "fabric"),
        mesh("rounded_box.obj", (d, 0.18, 0.27), (0.0, width / 2 - 0.09, 0.485), "fabric"),
        mesh("rounded_box.obj", (d, 0.18, 0.27), (0.0, -width / 2 + 0.09, 0.485), "fabric"),
    ]
    inner = width - 0.36
    cw = inner / n
    for i in range(n):
        y = -inner / 2 + cw * (i + 0.5)
        parts.append(mesh("rounded_box.obj", (d - 0.24, cw - 0.015, 0.13), (0.1, y, 0.415), "cushion"))
        parts.append(mesh("rounded_box.obj", (0.14, cw - 0.015, 0.3), (-d / 2 + 0.29, y, 0.63), "cushion", rpy=(0, -0.12, 0)))
    return ModelSpec(
        name,
        "chair",
        tuple(parts),
        {"feet": _rgb("2b1d14"), "fabric": _rgb("5a6b7d"), "cushion": _rgb("6f8196")},
        "fabric",
        palette=(_rgb("5a6b7d"), _rgb("7a5c45"), _rgb("3f5e4a"), _rgb("8c2f39"), _rgb("b8a98f"), _rgb("4b4b4b")),
        description=description,
    )


def _door() -> ModelSpec:
    # In a wall opening 1.0 m wide and 2.1 m high; frame as deep as the wall (0.3 m).
    parts = [
        box((0.3, 0.06, 2.1), (0.0, 0.47, 1.05), "frame"),
        box((0.3, 0.06, 2.1), (0.0, -0.47, 1.05), "frame"),
        box((0.3, 1.0, 0.06), (0.0, 0.0, 2.07), "frame"),
        box((0.04, 0.88, 2.02), (0.0, 0.0, 1.01), "panel"),
    ]
    for sx in (1.0, -1.0):
        for zc in (1.45, 0.55):
            parts.append(box((0.008, 0.3, 0.7), (sx * 0.022, 0.19, zc), "trim"))
            parts.append(box((0.008, 0.3, 0.7), (sx * 0.022, -0.19, zc), "trim"))
        parts.append(cyl(0.028, 0.012, (sx * 0.026, 0.36, 1.0), "metal", rpy=(0, PI / 2, 0)))
        parts.append(cyl(0.01, 0.11, (sx * 0.045, 0.32, 1.0), "metal", rpy=(PI / 2, 0, 0)))
    return ModelSpec(
        "door",
        "door",
        tuple(parts),
        {"frame": _rgb("e8e4dc"), "panel": _rgb("8a5a35"), "trim": _rgb("7a4e2d"), "metal": _rgb("c0c0c8")},
        "panel",
        palette=(_rgb("8a5a35"), _rgb("f2f0eb"), _rgb("5c3b22"), _rgb("9aa5ad"), _rgb("2f4858"), _rgb("c19a6b")),
        in_wall=True,
        description="closed door (panel 0.88 × 2.02 m) in a 0.3 m deep frame; fills a wall opening 1.0 × 2.1 m",
    )


def _rubber_duck() -> ModelSpec:
    s = 0.065  # the pybullet_data duck scaled to 0.11 × 0.075 × 0.10 m, head toward +x
    p = mesh(
        "pybullet_data:duck.obj",
        (s, s, s),
        (-0.0087, -0.0024, -0.0065),
        "duck",
        rpy=(PI / 2, 0, PI),
        collision="pybullet_data:duck_vhacd.obj",
    )
    return ModelSpec(
        "rubber_duck",
        "duck",
        (p,),
        {"duck": (1.0, 1.0, 1.0)},
        "duck",
        palette=((1.0, 1.0, 1.0), (1.0, 0.9, 0.6), (1.0, 0.8, 0.8), (0.85, 1.0, 0.85)),
        description="rubber duck (pybullet_data mesh, 0.11 × 0.075 × 0.10 m): below the LIDAR plane",
    )


def _person() -> ModelSpec:
    parts = []
    for y in (0.116, -0.116):
        parts += [
            box((0.26, 0.1, 0.07), (0.04, y, 0.035), "shoes"),
            cyl(0.07, 0.45, (0.0, y, 0.295), "pants"),
            cyl(0.085, 0.45, (0.0, y * 0.92, 0.73), "pants"),
        ]
    for s in (1.0, -1.0):
        parts += [
            caps(0.05, 0.24, (0.0, s * 0.255, 1.36), "shirt", rpy=(s * 0.08, 0, 0)),
            caps(0.042, 0.22, (0.02, s * 0.27, 1.1), "skin", rpy=(s * 0.02, -0.1, 0)),
            sph(0.05, (0.035, s * 0.272, 0.93), "skin"),
            sph(0.012, (0.09, s * 0.032, 1.69), "hair"),
        ]
    parts += [
        box((0.22, 0.36, 0.15), (0.0, 0.0, 0.95), "pants"),
        mesh("rounded_box.obj", (0.24, 0.42, 0.52), (0.0, 0.0, 1.28), "shirt"),
        cyl(0.05, 0.08, (0.0, 0.0, 1.57), "skin"),
        ell((0.095, 0.085, 0.115), (0.0, 0.0, 1.67), "skin"),
        ell((0.1, 0.09, 0.075), (-0.015, 0.0, 1.74), "hair"),
    ]
    return ModelSpec(
        "person",
        "person",
        tuple(parts),
        {"shoes": _rgb("222222"), "pants": _rgb("2d3e5e"), "shirt": _rgb("c0392b"), "skin": _rgb("e0b08f"), "hair": _rgb("3b2a1a")},
        "shirt",
        palette=(_rgb("c0392b"), _rgb("27ae60"), _rgb("2980b9"), _rgb("f1c40f"), _rgb("ecf0f1"), _rgb("8e44ad"), _rgb("34495e")),
        legged=True,
        description="standing person, 1.8 m, facing +x; lower legs r 0.07 m at y = ±0.116 m",
    )


def _extinguisher() -> ModelSpec:
    parts = (
        cyl(0.092, 0.03, (0, 0, 0.015), "black"),
        cyl(0.09, 0.56, (0, 0, 0.31), "red"),
        cyl(0.0915, 0.16, (0, 0, 0.33), "label"),
        ell((0.09, 0.09, 0.06), (0, 0, 0.59), "red"),
        cyl(0.03, 0.05, (0, 0, 0.665), "metal"),
        box((0.07, 0.05, 0.05), (0, 0, 0.71), "metal"),
        box((0.16, 0.025, 0.012), (0.03, 0, 0.752), "black", rpy=(0, -0.2, 0)),
        box((0.12, 0.025, 0.012), (0.02, 0, 0.726), "black"),
        caps(0.013, 0.42, (-0.105, 0, 0.47), "black"),
        cyl(0.018, 0.06, (-0.105, 0, 0.23), "black"),
    )
    return ModelSpec(
        "fire_extinguisher",
        "extinguisher",
        parts,
        {"black": _rgb("1a1a1a"), "red": _rgb("c1121f"), "label": _rgb("f0f0f0"), "metal": _rgb("9a9a9a")},
        "red",
        palette=(_rgb("c1121f"), _rgb("d62828"), _rgb("a4161a"), _rgb("e5383b")),
        description="fire extinguisher, cylinder r 0.09 m, 0.76 m tall, with hose",
    )


def _flowers() -> ModelSpec:
    parts = [
        mesh("frustum.obj", (0.085, 0.085, 0.22), (0, 0, 0.11), "pot", rpy=(PI, 0, 0)),
        cyl(0.09, 0.025, (0, 0, 0.21), "pot"),
        cyl(0.078, 0.01, (0, 0, 0.22), "soil"),
    ]
    stems = [  # (top x, top y, top z, head yaw)
        (0.03, 0.0, 0.9, 0.0),
        (-0.02, 0.05, 0.78, 1.0),
        (0.0, -0.05, 0.66, -0.9),
    ]
    for i, (tx, ty, tz, yaw) in enumerate(stems):
        base = np.array([0.0, 0.0, 0.22])
        top = np.array([tx, ty, tz])
        d = top - base
        length = float(np.linalg.norm(d))
        pitch = float(math.atan2(math.hypot(d[0], d[1]), d[2]))
        az = float(math.atan2(d[1], d[0]))
        mid = (base + top) / 2
        parts.append(cyl(0.008, length, tuple(mid), "stem", rpy=(0, pitch, az)))
        for k, frac in enumerate((0.35, 0.6)):
            p = base + d * frac
            side = 1.0 if (i + k) % 2 == 0 else -1.0
            parts.append(
                ell((0.065, 0.028, 0.006), (p[0] + side * 0.03 * math.sin(yaw + 1), p[1] + side * 0.03 * math.cos(yaw + 1), p[2]),
                    "leaf", rpy=(0.3 * side, -0.4, yaw + side * 1.2))
            )
        # the head faces outward along `yaw`, tilted 0.45 rad up
        n = np.array([math.cos(yaw) * math.cos(0.45), math.sin(yaw) * math.cos(0.45), math.sin(0.45)])
        hp = top + n * 0.01
        rpy = (0.0, PI / 2 - 0.45, yaw)
        parts.append(mesh("flower_head.obj", (0.09, 0.09, 0.2), tuple(hp), "petals", rpy=rpy))
        parts.append(cyl(0.038, 0.022, tuple(hp + n * 0.008), "seeds", rpy=rpy))
    return ModelSpec(
        "potted_flowers",
        "flowers",
        tuple(parts),
        {
            "pot": _rgb("b5542d"),
            "soil": _rgb("3b2a1a"),
            "stem": _rgb("4f7f2a"),
            "leaf": _rgb("3f8f2f"),
            "petals": _rgb("f5c400"),
            "seeds": _rgb("4a2c12"),
        },
        "petals",
        palette=(_rgb("f5c400"), _rgb("ff8c00"), _rgb("e63946"), _rgb("ff69b4"), _rgb("f8f8f8"), _rgb("9b5de5")),
        description="three sunflowers in a terracotta pot (pot 0.17 m, 0.95 m tall)",
    )


_BOOK_COLORS = [_rgb(h) for h in ("8e2424", "1f4e79", "2e7d32", "c9a227", "5d4037", "6a1b9a", "e0e0e0", "37474f", "ad1457")]


def _bookshelf() -> ModelSpec:
    # Webots 'cabinet' bookshelf: 1.0 wide (y), 0.4 deep (x), 2.32 high; open toward +x.
    parts = [
        box((0.02, 1.0, 2.32), (-0.19, 0.0, 1.16), "wood"),
        box((0.4, 0.02, 2.32), (0.0, 0.49, 1.16), "wood"),
        box((0.4, 0.02, 2.32), (0.0, -0.49, 1.16), "wood"),
        box((0.02, 0.96, 0.08), (0.18, 0.0, 0.04), "wood"),
    ]
    for z in (0.09, 0.52, 0.96, 1.40, 1.84, 2.31):
        parts.append(box((0.38, 0.96, 0.02), (0.01, 0.0, z), "wood"))
    rng = np.random.default_rng(7)  # fixed: the books are part of the model
    for shelf_z in (0.53, 0.97, 1.41, 1.85):
        y = -0.46 + float(rng.uniform(0.0, 0.15))
        while True:
            w = float(rng.uniform(0.03, 0.06))
            h = float(rng.uniform(0.2, 0.34))
            if y + w > 0.46:
                break
            k = int(rng.integers(len(_BOOK_COLORS)))
            parts.append(box((float(rng.uniform(0.18, 0.26)), w - 0.004, h), (-0.05, y + w / 2, shelf_z + h / 2), f"book{k}"))
            y += w
            if rng.random() < 0.12:
                y += float(rng.uniform(0.05, 0.2))
    colors = {"wood": _rgb("a47551")}
    colors.update({f"book{k}": c for k, c in enumerate(_BOOK_COLORS)})
    return ModelSpec(
        "bookshelf",
        "shelf",
        tuple(parts),
        colors,
        "wood",
        palette=(_rgb("a47551"), _rgb("f2efe9"), _rgb("5c4033"), _rgb("d9b99b"), _rgb("333333")),
        description="open bookshelf 1.0 × 0.4 × 2.32 m with books; the LIDAR sees a U (back and sides)",
    )


def _low_shelf() -> ModelSpec:
    parts = [
        box((0.35, 0.02, 1.1), (0.0, 0.59, 0.55), "wood"),
        box((0.35, 0.02, 1.1), (0.0, -0.59, 0.55), "wood"),
        box((0.02, 1.2, 1.1), (-0.165, 0.0, 0.55), "wood"),
        box((0.02, 0.4, 1.06), (0.0, 0.0, 0.55), "wood"),
    ]
    for z in (0.04, 0.38, 0.72, 1.09):
        parts.append(box((0.35, 1.2, 0.025), (0.0, 0.0, z), "wood"))
    rng = np.random.default_rng(11)
    for z0 in (0.4, 0.74):
        for side in (-1, 1):
            y = side * 0.05
            for _ in range(int(rng.integers(4, 8))):
                w = float(rng.uniform(0.03, 0.06))
                h = float(rng.uniform(0.18, 0.28))
                k = int(rng.integers(len(_BOOK_COLORS)))
                parts.append(box((0.2, w - 0.004, h), (-0.04, y + side * w / 2, z0 + h / 2), f"book{k}"))
                y += side * w
    colors = {"wood": _rgb("f2efe9")}
    colors.update({f"book{k}": c for k, c in enumerate(_BOOK_COLORS)})
    return ModelSpec(
        "low_shelf",
        "shelf",
        tuple(parts),
        colors,
        "wood",
        palette=(_rgb("f2efe9"), _rgb("a47551"), _rgb("333333"), _rgb("7a8b99")),
        description="low two-column bookcase 1.2 × 0.35 × 1.1 m",
    )


# -- unclassified models ----------------------------------------------------------------------


def _fridge() -> ModelSpec:
    parts = (
        box((0.66, 0.7, 1.8), (-0.02, 0.0, 0.9), "body"),
        box((0.04, 0.68, 1.1), (0.33, 0.0, 1.235), "doors"),
        box((0.04, 0.68, 0.62), (0.33, 0.0, 0.36), "doors"),
        box((0.03, 0.03, 0.4), (0.365, -0.28, 1.0), "metal"),
        box((0.03, 0.03, 0.3), (0.365, -0.28, 0.5), "metal"),
    )
    return ModelSpec(
        "fridge", None, parts, {"body": _rgb("e9ecef"), "doors": _rgb("f8f9fa"), "metal": _rgb("8d99a6")}, "body",
        palette=(_rgb("e9ecef"), _rgb("b0b7bf"), _rgb("343a40")),
        description="fridge 0.7 × 0.7 × 1.8 m, doors toward +x",
    )


def _kitchen_counter() -> ModelSpec:
    L = 2.2
    parts = [
        box((0.6, L, 0.1), (-0.05, 0.0, 0.05), "plinth"),
        box((0.62, L, 0.61), (0.0, 0.0, 0.405), "cabinet"),
        box((0.7, L, 0.03), (0.0, 0.0, 0.725), "worktop"),
        box((0.02, 0.58, 0.55), (0.32, 0.0, 0.41), "oven"),
        box((0.03, 0.45, 0.02), (0.34, 0.0, 0.62), "metal"),
        box((0.5, 0.56, 0.008), (0.0, 0.0, 0.744), "oven"),
    ]
    for y in (-0.82, -0.5, 0.5, 0.82):
        parts.append(box((0.02, 0.3, 0.55), (0.32, y, 0.41), "doors"))
        parts.append(box((0.025, 0.015, 0.12), (0.34, y + (0.1 if y > 0 else -0.1), 0.58), "metal"))
    return ModelSpec(
        "kitchen_counter", None, tuple(parts),
        {"plinth": _rgb("2b2b2b"), "cabinet": _rgb("d8d2c4"), "worktop": _rgb("6b5b4b"), "oven": _rgb("151515"),
         "metal": _rgb("a9a9a9"), "doors": _rgb("efeae0")},
        "doors",
        palette=(_rgb("efeae0"), _rgb("5b7065"), _rgb("2f3e46"), _rgb("c9ada7")),
        description="kitchen run 2.2 m long (y) × 0.7 m deep, worktop at 0.74 m, oven in the middle, front toward +x",
    )


def _stool() -> ModelSpec:
    parts = [cyl(0.17, 0.04, (0, 0, 0.47), "seat")]
    for k in range(4):
        a = PI / 4 + k * PI / 2
        parts.append(cyl(0.018, 0.46, (0.12 * math.cos(a), 0.12 * math.sin(a), 0.23), "legs"))
    return ModelSpec("stool", None, tuple(parts), {"seat": _rgb("7b4b2a"), "legs": _rgb("2b2b2b")}, "seat",
                     palette=(_rgb("7b4b2a"), _rgb("c0392b"), _rgb("2c3e50"), _rgb("f0e6d2")),
                     legged=True, description="round stool, Ø 0.34 m, four legs")


def _trash_bin() -> ModelSpec:
    parts = (cyl(0.15, 0.42, (0, 0, 0.21), "body"), cyl(0.155, 0.03, (0, 0, 0.435), "lid"))
    return ModelSpec("trash_bin", None, parts, {"body": _rgb("6c757d"), "lid": _rgb("343a40")}, "body",
                     palette=(_rgb("6c757d"), _rgb("2a9d8f"), _rgb("e9c46a"), _rgb("264653")),
                     description="pedal bin Ø 0.3 m, 0.45 m tall")


def _cardboard_box() -> ModelSpec:
    parts = (box((0.45, 0.35, 0.32), (0, 0, 0.16), "box"), box((0.455, 0.06, 0.005), (0, 0, 0.3205), "tape"))
    return ModelSpec("cardboard_box", None, parts, {"box": _rgb("b8865b"), "tape": _rgb("d9c8a0")}, "box",
                     palette=(_rgb("b8865b"), _rgb("a47148"), _rgb("c9a27e")), description="cardboard box 0.45 × 0.35 × 0.32 m")


def _tv_stand() -> ModelSpec:
    parts = (
        box((0.4, 1.2, 0.45), (0, 0, 0.225), "stand"),
        box((0.2, 0.3, 0.04), (0, 0, 0.47), "screen"),
        box((0.04, 0.06, 0.12), (0, 0, 0.55), "screen"),
        box((0.05, 1.0, 0.58), (0, 0, 0.89), "screen"),
        box((0.005, 0.94, 0.52), (0.026, 0, 0.89), "display"),
    )
    return ModelSpec("tv_stand", None, parts, {"stand": _rgb("4a3b30"), "screen": _rgb("111111"), "display": _rgb("1c2833")},
                     "stand", palette=(_rgb("4a3b30"), _rgb("f0f0f0"), _rgb("2b2b2b")),
                     description="TV on a low cabinet 1.2 × 0.4 m, screen 1.0 × 0.58 m")


def _painting() -> ModelSpec:
    parts = (box((0.03, 0.8, 0.6), (0, 0, 1.5), "frame"), box((0.01, 0.7, 0.5), (0.016, 0, 1.5), "canvas"))
    return ModelSpec("painting", None, parts, {"frame": _rgb("3e2c1c"), "canvas": _rgb("4f86c6")}, "canvas",
                     palette=(_rgb("4f86c6"), _rgb("e76f51"), _rgb("2a9d8f"), _rgb("e9c46a"), _rgb("8d6cab")),
                     description="framed picture 0.8 × 0.6 m hanging at 1.2–1.8 m (invisible to the LIDAR)")


def _beacon() -> ModelSpec:
    parts = (cyl(0.05, 0.08, (0, 0, 0.04), "body"), cyl(0.02, 0.02, (0, 0, 0.09), "top"))
    return ModelSpec("beacon", None, parts, {"body": _rgb("2b2b2b"), "top": _rgb("8a8a8a")}, "body",
                     description="iRobot virtual-wall beacon Ø 0.1 m, 0.1 m tall (below the LIDAR plane)")


def _build_catalogue() -> dict[str, ModelSpec]:
    specs = [
        _soccer_ball(),
        _play_ball(),
        _dog(),
        _gnome(),
        _table(),
        _round_table(),
        _dining_chair(),
        _sofa("armchair", 1.1, 1, "armchair 1.0 deep × 1.1 wide × 0.8 m on 0.1 m feet, seat toward +x"),
        _sofa("sofa", 1.8, 2, "two-seat sofa 1.0 deep × 1.8 wide × 0.8 m on 0.1 m feet, seat toward +x"),
        _sofa("sofa3", 2.2, 3, "three-seat sofa 1.0 deep × 2.2 wide × 0.8 m on 0.1 m feet, seat toward +x"),
        _door(),
        _rubber_duck(),
        _person(),
        _extinguisher(),
        _flowers(),
        _bookshelf(),
        _low_shelf(),
        _fridge(),
        _kitchen_counter(),
        _stool(),
        _trash_bin(),
        _cardboard_box(),
        _tv_stand(),
        _painting(),
        _beacon(),
    ]
    return {s.name: s for s in specs}


#: name → spec, for every model a world file may use.
MODELS: dict[str, ModelSpec] = _build_catalogue()


def get_model(name: str) -> ModelSpec:
    """The catalogue entry; ``KeyError`` with the list of known models."""
    try:
        return MODELS[name]
    except KeyError:
        raise KeyError(f"unknown model {name!r} (known: {', '.join(sorted(MODELS))})") from None


def models_for_class(label: str | None) -> list[str]:
    """Model names whose class is ``label`` (``None``: the unclassified models)."""
    return [n for n, s in MODELS.items() if s.label == label]


# ----------------------------------------------------------------------------------------------
# Colours
# ----------------------------------------------------------------------------------------------


def parse_color(value: object) -> RGB:
    """``[r, g, b]`` in [0, 1], ``[R, G, B]`` in 0..255 (any value > 1), or ``"#rrggbb"``. ``ValueError`` otherwise."""
    if isinstance(value, str):
        h = value.strip().lstrip("#")
        if len(h) != 6:
            raise ValueError(f"colour {value!r}: expected '#rrggbb'")
        try:
            return _rgb(h)
        except ValueError:
            raise ValueError(f"colour {value!r}: expected '#rrggbb'") from None
    if isinstance(value, (list, tuple)) and len(value) == 3 and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) for v in value
    ):
        c = [float(v) for v in value]
        if not all(math.isfinite(v) and v >= 0 for v in c):
            raise ValueError(f"colour {value!r}: components must be finite and ≥ 0")
        if max(c) > 1.0:
            if max(c) > 255:
                raise ValueError(f"colour {value!r}: components above 255")
            c = [v / 255.0 for v in c]
        return (c[0], c[1], c[2])
    raise ValueError(f"colour {value!r}: expected [r, g, b] or '#rrggbb'")


def jitter_color(rgb: Sequence[float], rng: np.random.Generator, amount: float = 0.08) -> RGB:
    """Perturb hue, saturation and value by up to ``amount`` (hue by a quarter of it)."""
    h, s, v = colorsys.rgb_to_hsv(*[min(max(float(c), 0.0), 1.0) for c in rgb[:3]])
    h = (h + rng.uniform(-amount, amount) * 0.25) % 1.0
    s = min(max(s + rng.uniform(-amount, amount), 0.0), 1.0)
    v = min(max(v + rng.uniform(-amount, amount), 0.0), 1.0)
    r, g, b = colorsys.hsv_to_rgb(h, s, v)
    return (float(r), float(g), float(b))


def resolve_colors(spec: ModelSpec, color: Sequence[float] | None = None) -> dict[str, RGB]:
    """Role → RGB for one instance: the defaults, with ``color`` on the primary role."""
    colors = dict(spec.colors)
    if color is not None:
        colors[spec.primary] = (float(color[0]), float(color[1]), float(color[2]))
    return colors


# ----------------------------------------------------------------------------------------------
# Geometry without pybullet (trimesh)
# ----------------------------------------------------------------------------------------------


def mesh_path(ref: str) -> Path:
    """File path of a mesh reference (``"cone.obj"`` or ``"pybullet_data:duck.obj"``)."""
    if ref.startswith("pybullet_data:"):
        import pybullet_data

        return Path(pybullet_data.getDataPath()) / ref.split(":", 1)[1]
    return MESH_DIR / ref


@lru_cache(maxsize=None)
def _load_mesh(ref: str):
    import trimesh

    path = mesh_path(ref)
    if not path.is_file():
        raise FileNotFoundError(f"mesh {ref!r} not found at {path} (run scripts/make_object_meshes.py)")
    return trimesh.load(str(path), force="mesh", process=False)


def _rpy_matrix(rpy: Sequence[float]) -> NDArray[np.float64]:
    """R = Rz(yaw) · Ry(pitch) · Rx(roll), as pybullet's getQuaternionFromEuler."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def _part_trimesh(part: Part, scale: float):
    """The part as a trimesh in the model frame (``scale`` applied), or None for collision-only parts."""
    import trimesh

    d = part.dims
    if part.shape == "box":
        m = trimesh.creation.box(extents=[d[0] * scale, d[1] * scale, d[2] * scale])
    elif part.shape == "cylinder":
        m = trimesh.creation.cylinder(radius=d[0] * scale, height=d[1] * scale, sections=16)
    elif part.shape == "capsule":
        m = trimesh.creation.capsule(height=d[1] * scale, radius=d[0] * scale, count=[12, 8])
    elif part.shape == "sphere":
        m = trimesh.creation.uv_sphere(radius=d[0] * scale, count=[16, 10])
    elif part.shape == "mesh":
        m = _load_mesh(part.mesh).copy()
        m.apply_scale(np.asarray(d, dtype=np.float64) * scale)
    else:
        raise ValueError(f"unknown part shape {part.shape!r}")
    T = np.eye(4)
    T[:3, :3] = _rpy_matrix(part.rpy)
    T[:3, 3] = np.asarray(part.pos, dtype=np.float64) * scale
    m.apply_transform(T)
    return m


def model_parts_trimesh(name: str, scale: float = 1.0, color: Sequence[float] | None = None) -> list[tuple[object, RGB]]:
    """``[(trimesh.Trimesh, rgb)]`` of every visible part, in the model frame."""
    spec = get_model(name)
    colors = resolve_colors(spec, color)
    out = []
    for part in spec.parts:
        if part.role == COLLISION_ONLY:
            continue
        out.append((_part_trimesh(part, scale), colors.get(part.role, (0.7, 0.7, 0.7))))
    return out


def model_trimesh(name: str, scale: float = 1.0, color: Sequence[float] | None = None):
    """One coloured ``trimesh.Trimesh`` of the model (face colours), for the web view and exports."""
    import trimesh

    meshes = []
    for m, rgb in model_parts_trimesh(name, scale, color):
        m = trimesh.Trimesh(vertices=m.vertices, faces=m.faces, process=False)
        rgba = np.array([*(np.clip(rgb, 0, 1) * 255), 255], dtype=np.uint8)
        m.visual.face_colors = np.tile(rgba, (len(m.faces), 1))
        meshes.append(m)
    return trimesh.util.concatenate(meshes)


@lru_cache(maxsize=None)
def _footprint_and_z(name: str) -> tuple[NDArray[np.float64], float, float]:
    from shapely import MultiPoint

    spec = get_model(name)
    pts, zs = [], []
    for part in spec.parts:
        m = _part_trimesh(part, 1.0)
        pts.append(np.asarray(m.vertices)[:, :2])
        zs.append(np.asarray(m.vertices)[:, 2])
    hull = MultiPoint(np.vstack(pts)).convex_hull
    xy = np.asarray(hull.exterior.coords)[:-1]
    if hull.exterior.is_ccw is False:
        xy = xy[::-1]
    allz = np.concatenate(zs)
    return np.round(xy, 6), float(max(allz.min(), 0.0)), float(allz.max())


def model_footprint(name: str, scale: float = 1.0) -> NDArray[np.float64]:
    """``(K, 2)`` counter-clockwise convex footprint polygon in the model frame (metres)."""
    return _footprint_and_z(name)[0] * scale


def model_z_range(name: str, scale: float = 1.0) -> tuple[float, float]:
    """``(z_min, z_max)`` of the model above the floor."""
    _, z0, z1 = _footprint_and_z(name)
    return z0 * scale, z1 * scale


# ----------------------------------------------------------------------------------------------
# pybullet
# ----------------------------------------------------------------------------------------------


def _quat_mul(a: Sequence[float], b: Sequence[float]) -> tuple[float, float, float, float]:
    """Hamilton product of (x, y, z, w) quaternions."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def build_model_pybullet(
    client: int,
    name: str,
    x: float,
    y: float,
    yaw: float,
    *,
    z: float = 0.0,
    scale: float = 1.0,
    colors: dict[str, RGB] | None = None,
    mesh_file: Callable[[str, Sequence[float]], str] | None = None,
) -> list[tuple[int, str]]:
    """Create the model's static bodies in pybullet ``client``; returns ``[(body id, role)]``.

    Every part becomes one static body (mass 0) with its own visual (coloured by role) and
    collision shape. ``yaw`` in radians. ``mesh_file(path, mesh_scale)`` (optional) names the file a
    visual mesh is loaded from (the EGL renderer caches meshes by file name and would draw a second
    scale of the same file at the first one's: the simulator passes a per-scale alias).
    """
    import pybullet as p

    spec = get_model(name)
    colors = colors or resolve_colors(spec)
    q_yaw = p.getQuaternionFromEuler([0.0, 0.0, yaw])
    c, s = math.cos(yaw), math.sin(yaw)
    out: list[tuple[int, str]] = []
    for part in spec.parts:
        d = [v * scale for v in part.dims]
        collision_only = part.role == COLLISION_ONLY
        vis_kw: dict = {}
        col = -1
        if part.shape == "box":
            he = [d[0] / 2, d[1] / 2, d[2] / 2]
            vis_kw = dict(shapeType=p.GEOM_BOX, halfExtents=he)
            col_kw = dict(shapeType=p.GEOM_BOX, halfExtents=he)
        elif part.shape == "cylinder":
            vis_kw = dict(shapeType=p.GEOM_CYLINDER, radius=d[0], length=d[1])
            col_kw = dict(shapeType=p.GEOM_CYLINDER, radius=d[0], height=d[1])
        elif part.shape == "capsule":
            vis_kw = dict(shapeType=p.GEOM_CAPSULE, radius=d[0], length=d[1])
            col_kw = dict(shapeType=p.GEOM_CAPSULE, radius=d[0], height=d[1])
        elif part.shape == "sphere":
            vis_kw = dict(shapeType=p.GEOM_SPHERE, radius=d[0])
            col_kw = dict(shapeType=p.GEOM_SPHERE, radius=d[0])
        elif part.shape == "mesh":
            path = str(mesh_path(part.mesh))
            vis_kw = dict(shapeType=p.GEOM_MESH, fileName=mesh_file(path, d) if mesh_file else path, meshScale=d)
            if part.collision == "box":
                col_kw = dict(shapeType=p.GEOM_BOX, halfExtents=[d[0] / 2, d[1] / 2, d[2] / 2])
            elif part.collision in ("auto", ""):
                col_kw = dict(shapeType=p.GEOM_MESH, fileName=path, meshScale=d)
            elif part.collision == "none":
                col_kw = {}
            else:
                col_kw = dict(shapeType=p.GEOM_MESH, fileName=str(mesh_path(part.collision)), meshScale=d)
        else:
            raise ValueError(f"{name}: unknown part shape {part.shape!r}")
        if part.shape != "mesh" and part.collision == "none":
            col_kw = {}
        if col_kw:
            col = p.createCollisionShape(physicsClientId=client, **col_kw)
        vis = -1
        if not collision_only:
            rgb = colors.get(part.role, (0.7, 0.7, 0.7))
            vis = p.createVisualShape(physicsClientId=client, rgbaColor=[*np.clip(rgb, 0, 1), 1.0], **vis_kw)
        if vis < 0 and col < 0:
            continue
        px, py, pz = (v * scale for v in part.pos)
        wx, wy = x + c * px - s * py, y + s * px + c * py
        q = _quat_mul(q_yaw, p.getQuaternionFromEuler(part.rpy))
        body = p.createMultiBody(
            baseMass=0.0,
            baseCollisionShapeIndex=col,
            baseVisualShapeIndex=vis,
            basePosition=[wx, wy, z + pz],
            baseOrientation=q,
            physicsClientId=client,
        )
        out.append((body, part.role))
    return out


def class_models() -> dict[str, list[str]]:
    """Class name → its model names, for every class of :data:`CLASS_NAMES`."""
    return {c: models_for_class(c) for c in CLASS_NAMES}


def describe(names: Iterable[str] | None = None) -> list[dict]:
    """A table of the catalogue (name, class, legged, size, description), for docs and the CLI."""
    rows = []
    for n in names or MODELS:
        spec = get_model(n)
        fp = model_footprint(n)
        z0, z1 = model_z_range(n)
        rows.append(
            {
                "model": n,
                "class": spec.label or "-",
                "legged": spec.legged,
                "size_m": [round(float(np.ptp(fp[:, 0])), 3), round(float(np.ptp(fp[:, 1])), 3), round(z1 - z0, 3)],
                "description": spec.description,
            }
        )
    return rows


def world_visual_meshes(world) -> list[tuple[str, object]]:
    """``[(name, trimesh.Trimesh)]`` of a :class:`app.worlds.World` in the world frame, coloured:
    the floor, each wall (solid pieces and window panes), each obstacle and each object. For the web view."""
    import trimesh

    def colored(m, rgb):
        m = trimesh.Trimesh(vertices=m.vertices, faces=m.faces, process=False)
        rgba = np.array([*(np.clip(rgb, 0, 1) * 255), 255], dtype=np.uint8)
        m.visual.face_colors = np.tile(rgba, (len(m.faces), 1))
        return m

    def placed_box(extents, x, y, z, yaw):
        m = trimesh.creation.box(extents=extents)
        T = np.eye(4)
        T[:3, :3] = _rpy_matrix((0.0, 0.0, yaw))
        T[:3, 3] = (x, y, z)
        m.apply_transform(T)
        return m

    out: list[tuple[str, object]] = []
    xmin, ymin, xmax, ymax = world.bounds()
    out.append(("floor", colored(placed_box([xmax - xmin + 0.4, ymax - ymin + 0.4, 0.01], (xmin + xmax) / 2, (ymin + ymax) / 2, -0.005, 0.0), world.floor_color)))
    for i, w in enumerate(world.walls):
        parts = []
        for s0, s1, z0, z1, th, yaw in w.boxes():
            mx, my = w.point_at((s0 + s1) / 2)
            parts.append(colored(placed_box([s1 - s0, th, z1 - z0], mx, my, (z0 + z1) / 2, yaw), w.color or world.wall_color))
        for o in w.openings:
            if o.kind == "window":
                mx, my = w.point_at((o.start + o.end) / 2)
                parts.append(colored(placed_box([o.end - o.start, 0.02, o.top - o.bottom], mx, my, (o.bottom + o.top) / 2, w.yaw), (0.62, 0.78, 0.9)))
        if parts:
            out.append((f"wall_{i}_{w.name}", trimesh.util.concatenate(parts)))
    for i, o in enumerate(world.obstacles):
        if o.shape == "box":
            m = colored(placed_box(list(o.size), o.x, o.y, o.z + o.size[2] / 2, o.yaw), o.color or (0.6, 0.6, 0.6))
        elif o.shape == "cylinder":
            m = trimesh.creation.cylinder(radius=o.radius, height=o.height, sections=24)
            m.apply_translation([o.x, o.y, o.z + o.height / 2])
            m = colored(m, o.color or (0.6, 0.6, 0.6))
        else:
            m = model_trimesh(o.model, o.scale, o.color)
            m.apply_transform(_planar_matrix(o.x, o.y, o.yaw, o.z))
        out.append((f"obstacle_{i}_{o.name or o.model or o.shape}", m))
    for i, o in enumerate(world.objects):
        m = model_trimesh(o.model, o.scale, o.color)
        m.apply_transform(_planar_matrix(o.x, o.y, o.yaw, 0.0))
        out.append((f"object_{i}_{o.name or o.label}", m))
    return out


def _planar_matrix(x: float, y: float, yaw: float, z: float = 0.0) -> NDArray[np.float64]:
    T = np.eye(4)
    T[:3, :3] = _rpy_matrix((0.0, 0.0, yaw))
    T[:3, 3] = (x, y, z)
    return T
