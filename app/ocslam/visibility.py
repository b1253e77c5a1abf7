"""What a camera sees of a planar map, for the evaluation and the tour planner.

:func:`in_view_matrix` tells which objects (``(K, 2)`` footprints in the map frame) each planar camera pose
``[x, y, yaw]`` has in its horizontal field of view, in range and with a free line of sight past occluders;
:func:`image_columns` and :func:`point_columns` give the image columns a footprint or points span for a
pinhole camera, :func:`box_covers` whether a detector box covers such columns.

Example:
    >>> in_view_matrix(np.array([[0.0, 0.0, 0.0]]), [square_at_2m], [None], hfov_rad=1.04)   # (1, 1) bool
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import shapely
from shapely.geometry import Polygon

__all__ = ["box_covers", "footprint_polygon", "image_columns", "in_view_matrix", "point_columns"]


def footprint_polygon(footprint: np.ndarray) -> Polygon | None:
    """The shapely polygon of a ``(K, 2)`` footprint (repaired if self-intersecting), or ``None`` when it has
    fewer than 3 finite points or no area."""
    fp = np.asarray(footprint, dtype=np.float64).reshape(-1, 2)
    if len(fp) < 3 or not np.all(np.isfinite(fp)):
        return None
    poly = Polygon(fp)
    if not poly.is_valid:
        poly = poly.buffer(0)
    return poly if poly.area > 0 else None


_VIEW_SAMPLES: dict[tuple[bytes, tuple[int, ...], float, int], np.ndarray] = {}


def _view_samples(footprint: np.ndarray, shrink: float = 0.6, n: int = 8) -> np.ndarray:
    """``(S, 2)`` points an observer must see of a footprint: its centroid and ``n`` points of its
    boundary pulled ``shrink`` of the way towards the centroid (so touching neighbours do not hide them).
    Remembered per footprint (callers ask for the same footprints pose after pose); read-only."""
    fp = np.ascontiguousarray(footprint, dtype=np.float64)
    key = (fp.tobytes(), fp.shape, float(shrink), int(n))
    out = _VIEW_SAMPLES.get(key)
    if out is None:
        if len(_VIEW_SAMPLES) >= 4096:
            _VIEW_SAMPLES.clear()
        out = _VIEW_SAMPLES[key] = _compute_view_samples(fp, shrink, n)
        out.flags.writeable = False
    return out


def _compute_view_samples(footprint: np.ndarray, shrink: float, n: int) -> np.ndarray:
    poly = footprint_polygon(footprint)
    if poly is None:
        fp = np.asarray(footprint, dtype=np.float64).reshape(-1, 2)
        return fp.mean(axis=0, keepdims=True) if len(fp) else np.zeros((0, 2))
    c = np.array(poly.centroid.coords[0])
    ring = poly.exterior
    pts = np.array([ring.interpolate(t, normalized=True).coords[0] for t in np.linspace(0, 1, n, endpoint=False)])
    return np.vstack([c, c + shrink * (pts - c)])


def in_view_matrix(
    T_map_camera: np.ndarray,
    footprints: Sequence[np.ndarray],
    occluders: Sequence[Any],
    hfov_rad: float,
    max_range_m: float = 4.0,
    min_range_m: float = 0.2,
    min_visible: float = 0.4,
) -> np.ndarray:
    """Which objects each camera pose sees: ``(P, N)`` bool.

    ``T_map_camera``: ``(P, 3)`` planar camera poses ``[x, y, yaw]`` (yaw = optical axis) in the map
    frame; ``footprints``: ``N`` polygons ``(K, 2)`` in the map frame; ``occluders[j]``: a shapely
    geometry that hides object ``j`` (walls, and the furniture tall enough to hide it; it must not
    contain object ``j`` itself) or ``None``. An object is in view when at least ``min_visible`` of its
    sample points (:func:`_view_samples`) lie inside the horizontal field of view, between
    ``min_range_m`` and ``max_range_m``, with a free line of sight. A planar test: heights only enter
    through the caller's choice of occluders.
    """
    poses = np.asarray(T_map_camera, dtype=np.float64).reshape(-1, 3)
    out = np.zeros((len(poses), len(footprints)), dtype=bool)
    if not len(poses):
        return out
    for j, fp in enumerate(footprints):
        s = _view_samples(fp)
        if not len(s):
            continue
        d = s[None, :, :] - poses[:, None, :2]  # (P, S, 2)
        rng = np.hypot(d[..., 0], d[..., 1])
        bearing = np.arctan2(d[..., 1], d[..., 0]) - poses[:, None, 2]
        bearing = (bearing + np.pi) % (2 * np.pi) - np.pi
        ok = (np.abs(bearing) <= hfov_rad / 2) & (rng >= min_range_m) & (rng <= max_range_m)
        occ = occluders[j] if j < len(occluders) else None
        if occ is not None and not occ.is_empty and ok.any():
            pi, si = np.nonzero(ok)
            lines = shapely.linestrings(np.stack([poses[pi, :2], s[si]], axis=1))
            shapely.prepare(occ)
            ok[pi, si] = ~shapely.intersects(occ, lines)
        out[:, j] = ok.mean(axis=1) >= min_visible - 1e-9
    return out


def image_columns(T_map_camera: np.ndarray, footprint: np.ndarray, fx: float, cx: float, width: int) -> tuple[float, float] | None:
    """The image-column interval ``(u0, u1)`` that a footprint spans for a planar camera pose
    ``[x, y, yaw]`` (pinhole, optical axis along ``yaw``, columns growing to the right), clipped to
    ``[0, width]``; ``None`` when it lies entirely behind the camera or outside the image."""
    x, y, yaw = (float(v) for v in np.asarray(T_map_camera).reshape(3))
    fp = np.asarray(footprint, dtype=np.float64).reshape(-1, 2) - (x, y)
    c, s = np.cos(yaw), np.sin(yaw)
    fwd = c * fp[:, 0] + s * fp[:, 1]
    left = -s * fp[:, 0] + c * fp[:, 1]
    m = fwd > 0.05
    if not m.any():
        return None
    u = cx - fx * left[m] / fwd[m]
    if (~m).any():  # part behind the camera: the footprint reaches the image's edge on its side
        u = np.r_[u, 0.0 if (left[~m] > 0).any() else width]
        if (left[~m] > 0).any() and (left[~m] < 0).any():
            u = np.r_[u, 0.0, float(width)]
    u0, u1 = float(np.clip(u.min(), 0, width)), float(np.clip(u.max(), 0, width))
    return (u0, u1) if u1 - u0 > 0 else None


def point_columns(T_map_camera: np.ndarray, points: np.ndarray, fx: float, cx: float) -> np.ndarray:
    """``(M,)`` image columns of ``(M, 2)`` map points for a planar camera pose ``[x, y, yaw]``
    (``nan`` for points behind the camera)."""
    x, y, yaw = (float(v) for v in np.asarray(T_map_camera).reshape(3))
    d = np.asarray(points, dtype=np.float64).reshape(-1, 2) - (x, y)
    c, s = np.cos(yaw), np.sin(yaw)
    fwd = c * d[:, 0] + s * d[:, 1]
    left = -s * d[:, 0] + c * d[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(fwd > 0.05, cx - fx * left / fwd, np.nan)


def box_covers(cols: tuple[float, float] | None, box_x1: float, box_x2: float, min_overlap: float = 0.5) -> bool:
    """A box ``[x1, x2]`` covers an object's columns when their overlap is at least ``min_overlap`` of
    the narrower of the two."""
    if cols is None:
        return False
    inter = min(cols[1], box_x2) - max(cols[0], box_x1)
    narrow = max(min(cols[1] - cols[0], box_x2 - box_x1), 1e-6)
    return inter >= min_overlap * narrow
