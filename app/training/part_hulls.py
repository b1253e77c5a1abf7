"""An object's silhouette drawn from its convex parts with OpenCV, without a renderer.

Every catalogue model is a set of rigid parts; almost all of them are convex (boxes, cylinders, capsules,
spheres, and meshes such as the ellipsoid or the rounded box), and a convex part's silhouette through a
pinhole camera is the convex hull of its projected vertices. The union of those hulls, filled into a pixel
grid, is the model's silhouette: :func:`raster_silhouette`. Filling a few dozen hulls costs far less than a
renderer's pass over the same triangles (TinyRenderer: 0.3–2 ms a window, most of it the meshes' triangles
and the window's pixels), and the cost barely grows with the window's pixels.

A model with a part that is not convex (the duck, the flowers' heads) has no hulls (:func:`model_hulls`
returns ``None``) and is left to the renderer. The fill differs from a renderer's by the pixels the outline
crosses (OpenCV fills a pixel the outline touches; a renderer tests its centre), which the caller's error
bound covers (:meth:`app.training.silhouettes.SilhouetteRenderer.measure`).

Example:
    >>> hulls = model_hulls("dining_chair", 1.0)          # ModelHulls in the model frame, or None
    >>> mask = raster_silhouette(hulls, T_cam_model, K, (u0, v0, u1, v1), 64, 32, near=0.05)  # (32, 64) bool
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import cv2
import numpy as np
from numpy.typing import NDArray

from app.world.models.catalogue import get_model
from app.world.models.meshes import part_trimesh, rpy_matrix
from app.world.models.parts import COLLISION_ONLY, Part

__all__ = ["ModelHulls", "model_hulls", "raster_silhouette"]

#: a mesh counts as convex when its convex hull's volume exceeds its own by at most this share (the
#: soccer ball's panels are dented by 0.07 %: a sub-pixel difference in any silhouette)
CONVEX_VOLUME_TOLERANCE = 0.005
#: sections of a cylinder's or a capsule's circles and a sphere's rings (points on the true surface)
ROUND_SECTIONS = 24
#: fixed-point bits of the fill's vertex coordinates (OpenCV's ``shift``): 1/256 render pixel
_SHIFT = 8
#: OpenCV fills in 16-bit fixed point: vertices farther out than this (render pixels) would overflow it
_COORD_LIMIT = float(1 << 14)


@dataclass(frozen=True)
class ModelHulls:
    """A model's visible parts as convex point sets in the model frame (x forward, z up, origin on the
    floor): ``points`` ``(N, 3)`` metres, part ``k`` is ``points[starts[k]:starts[k + 1]]``."""

    points: NDArray[np.float64]
    starts: tuple[int, ...]

    def __len__(self) -> int:
        return len(self.starts) - 1


def _part_points(part: Part, scale: float) -> NDArray[np.float64] | None:
    """The vertices of the part's convex hull in the model frame, or ``None`` if the part is not convex."""
    import trimesh

    d = [v * scale for v in part.dims]
    if part.shape == "mesh":
        m = part_trimesh(part, scale)
        m = trimesh.Trimesh(vertices=m.vertices, faces=m.faces, process=True)
        hull = m.convex_hull
        if not m.is_watertight or hull.volume > m.volume * (1.0 + CONVEX_VOLUME_TOLERANCE):
            return None
        return np.asarray(hull.vertices, dtype=np.float64)
    if part.shape == "box":
        local = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)]) * d
    else:
        a = np.linspace(0.0, 2.0 * np.pi, ROUND_SECTIONS, endpoint=False)
        ring = np.c_[np.cos(a), np.sin(a)]
        if part.shape == "cylinder":
            local = np.r_[np.c_[d[0] * ring, np.full(len(a), -d[1] / 2)], np.c_[d[0] * ring, np.full(len(a), d[1] / 2)]]
        elif part.shape in ("sphere", "capsule"):
            r = d[0]
            el = np.linspace(-np.pi / 2, np.pi / 2, ROUND_SECTIONS // 2 + 1)[1:-1]
            sph = np.concatenate([np.c_[r * np.cos(e) * ring, np.full(len(a), r * np.sin(e))] for e in el])
            sph = np.r_[sph, [[0.0, 0.0, -r], [0.0, 0.0, r]]]
            half = d[1] / 2 if part.shape == "capsule" else 0.0
            local = np.r_[sph + [0.0, 0.0, half], sph - [0.0, 0.0, half]] if half else sph
        else:
            raise ValueError(f"unknown part shape {part.shape!r}")
    R = rpy_matrix(part.rpy)
    return local @ R.T + np.asarray(part.pos, dtype=np.float64) * scale


@cache
def model_hulls(model: str, scale: float = 1.0) -> ModelHulls | None:
    """The visible parts of catalogue model ``model`` at ``scale`` as convex point sets, or ``None`` if one
    of them is not convex (its silhouette is not the union of hulls). Cached per (model, scale)."""
    chunks = []
    for part in get_model(model).parts:
        if part.role == COLLISION_ONLY:
            continue
        pts = _part_points(part, float(scale))
        if pts is None:
            return None
        chunks.append(pts)
    if not chunks:
        return None
    starts = np.cumsum([0] + [len(c) for c in chunks])
    return ModelHulls(np.concatenate(chunks), tuple(int(s) for s in starts))


def raster_silhouette(
    hulls: ModelHulls,
    T_cam_model: NDArray[np.float64],
    K: NDArray[np.float64],
    window: tuple[int, int, int, int],
    rw: int,
    rh: int,
    near: float,
) -> NDArray[np.bool_] | None:
    """The model's silhouette on the pixel ``window`` ``(u0, v0, u1, v1)`` of camera ``K`` (image pixels,
    exclusive ends), drawn on a grid of ``rw × rh`` render pixels (``(rh, rw)`` bool, row 0 at ``v0``).

    ``T_cam_model`` ``(4, 4)``: the model frame in the camera's optical frame (z forward, x right, y down).
    ``None`` when a point lies at or behind the near plane (its hull is unbounded there) or projects too
    far out for fixed-point coordinates: the caller renders those."""
    P = hulls.points @ T_cam_model[:3, :3].T + T_cam_model[:3, 3]
    z = P[:, 2]
    if z.min() <= near:
        return None
    u0, v0, u1, v1 = window
    # continuous render-grid coordinates; OpenCV's pixel j has its centre at coordinate j
    gx = (K[0, 0] * P[:, 0] / z + K[0, 2] - u0) * (rw / (u1 - u0)) - 0.5
    gy = (K[1, 1] * P[:, 1] / z + K[1, 2] - v0) * (rh / (v1 - v0)) - 0.5
    if np.abs(gx).max() >= _COORD_LIMIT or np.abs(gy).max() >= _COORD_LIMIT:
        return None
    q = np.rint(np.c_[gx, gy] * (1 << _SHIFT)).astype(np.int32)
    mask = np.zeros((rh, rw), dtype=np.uint8)
    s = hulls.starts
    for k in range(len(s) - 1):
        cv2.fillConvexPoly(mask, cv2.convexHull(q[s[k]:s[k + 1]]), 1, lineType=cv2.LINE_8, shift=_SHIFT)
    return mask.astype(bool)
