"""Model bodies in pybullet: one static body per part, coloured per part, with collision shapes.

So LIDAR rays and the robot meet the legs of a table, not its bounding box. pybullet is imported
inside :func:`build_model_pybullet` only.

Example:
    >>> bodies = build_model_pybullet(client, "dog", 1.0, 2.0, 0.5)     # [(body id, role)]
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from app.world.models.catalogue import get_model
from app.world.models.colors import resolve_colors
from app.world.models.meshes import mesh_path
from app.world.models.parts import COLLISION_ONLY, RGB

__all__ = ["build_model_pybullet", "body_flags"]


def body_flags(p: Any) -> int:
    """The ``flags`` for the bodies this project creates in pybullet module ``p`` (``createMultiBody``, and
    ``loadURDF`` for the dataset's distractors): ``URDF_ENABLE_CACHED_GRAPHICS_SHAPES``.

    pybullet converts each new body's visual shapes twice: for the renderer that draws the camera images
    (TinyRenderer or the EGL plugin) and for the physics server's own GUI. Our clients are DIRECT, with no GUI,
    so the second conversion (tessellating every cylinder, sphere and capsule: 0.3–0.5 ms a body) builds
    nothing; with this flag the server reuses the first body's (empty) result for the bodies after it. The
    renderer's conversion, and so every image and segmentation mask, is unchanged
    (``tests/test_sim_world.py::test_cached_graphics_flag_leaves_the_images_unchanged``)."""
    return int(p.URDF_ENABLE_CACHED_GRAPHICS_SHAPES)


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
    flags = body_flags(p)
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
            flags=flags,
            physicsClientId=client,
        )
        out.append((body, part.role))
    return out
