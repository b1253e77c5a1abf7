"""Model and world meshes without pybullet (trimesh): for the web view, exports and footprints.

Example:
    >>> m = model_trimesh("dog")                  # one coloured trimesh in the model frame
    >>> parts = world_visual_meshes(world)        # [(name, trimesh)] in the world frame
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import cache
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from app.world.models.catalogue import get_model
from app.world.models.colors import resolve_colors
from app.world.models.parts import COLLISION_ONLY, MESH_DIR, RGB, Part

__all__ = ["mesh_path", "part_trimesh", "model_parts_trimesh", "model_trimesh", "world_visual_meshes", "rpy_matrix"]


def mesh_path(ref: str) -> Path:
    """File path of a mesh reference (``"cone.obj"`` or ``"pybullet_data:duck.obj"``)."""
    if ref.startswith("pybullet_data:"):
        import pybullet_data

        return Path(pybullet_data.getDataPath()) / ref.split(":", 1)[1]
    return MESH_DIR / ref


@cache
def _load_mesh(ref: str):
    import trimesh

    path = mesh_path(ref)
    if not path.is_file():
        raise FileNotFoundError(f"mesh {ref!r} not found at {path} (run scripts/make_object_meshes.py)")
    return trimesh.load(str(path), force="mesh", process=False)


def rpy_matrix(rpy: Sequence[float]) -> NDArray[np.float64]:
    """R = Rz(yaw) · Ry(pitch) · Rx(roll), as pybullet's getQuaternionFromEuler."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def part_trimesh(part: Part, scale: float):
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
    T[:3, :3] = rpy_matrix(part.rpy)
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
        out.append((part_trimesh(part, scale), colors.get(part.role, (0.7, 0.7, 0.7))))
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


def world_visual_meshes(world) -> list[tuple[str, object]]:
    """``[(name, trimesh.Trimesh)]`` of a :class:`app.world.types.World` in the world frame, coloured:
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
        T[:3, :3] = rpy_matrix((0.0, 0.0, yaw))
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
    T[:3, :3] = rpy_matrix((0.0, 0.0, yaw))
    T[:3, 3] = (x, y, z)
    return T
