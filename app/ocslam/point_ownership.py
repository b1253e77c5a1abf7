"""Which bounding area owns which LIDAR point (improved mode; paper §2.5.2's "points inside the area").

:func:`assign_points` tests every point against every area (by bearing and range about the apex, exact
as the areas' polygons) and, where areas overlap, gives each point to the one that explains it best: the
area whose bottom-edge range fits the point's range, then the nearest, then the one whose bisector is
closest. :func:`contest_by_range` is the softer contest used with point ownership (a table's leg in
front of a chair seen behind it stays the table's). All in ``base_scan`` (2D, metres).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import shapely
from numpy.typing import NDArray

from app.ocslam.projection import BoundingArea, _in_wedges

FloatArray = NDArray[np.float64]


def assign_points(
    points_scan: FloatArray,
    areas: Sequence[BoundingArea],
    exclusive: bool = True,
    range_tolerance: float = 0.25,
) -> NDArray[np.bool_]:
    """Which points lie in which areas: ``(N, 2)`` points in ``base_scan`` → ``(N, A)`` bool.

    Containment is strict (a point on the outline is outside), as ``shapely.contains_xy`` on the areas'
    polygons: simple wedges are tested by bearing and range about the apex (:func:`_in_wedges`), the
    points near their outline and the other areas on the polygon itself. With ``exclusive`` (improved mode)
    a point inside several areas goes to one only: the area whose expected range (its near range
    from the bottom edge, ``[near_lo·(1−tol), near_hi·(1+tol)]``) explains the point best; on a tie
    the area nearest the camera (smallest near range), then the one whose bisector is closest, then
    the higher confidence.
    Without ``exclusive`` (seed mode) a point may belong to several areas.
    """
    pts = np.asarray(points_scan, dtype=np.float64).reshape(-1, 2)
    A = len(areas)
    inside = np.zeros((len(pts), A), dtype=bool)
    if len(pts) == 0 or A == 0:
        return inside
    finite = np.all(np.isfinite(pts), axis=1)
    all_finite = bool(finite.all())
    # simple wedges (all of them, but for degenerate boxes) by bearing and range, a whole apex at once;
    # points within _WEDGE_EPS of an outline, and other areas, on the polygon
    by_apex: dict[tuple[float, float], list[int]] = {}
    for k, area in enumerate(areas):
        w = area._wedge_test
        if w is not None:
            by_apex.setdefault(w.apex, []).append(k)
        else:
            inside[:, k] = shapely.contains_xy(area.polygon, pts[:, 0], pts[:, 1]) & finite
    fin = pts if all_finite else np.where(finite[:, None], pts, 0.0)
    for ks in by_apex.values():
        tests = [areas[k]._wedge_test for k in ks]
        ins, unsure = _in_wedges(fin, [w for w in tests if w is not None])
        if not all_finite:
            ins &= finite[:, None]
            unsure &= finite[:, None]
        if unsure.any():
            for col, k in enumerate(ks):
                near_outline = np.flatnonzero(unsure[:, col])
                if len(near_outline):
                    p = pts[near_outline]
                    ins[near_outline, col] = shapely.contains_xy(areas[k].polygon, p[:, 0], p[:, 1])
        if len(ks) == A:
            inside = ins  # every area (ks: 0, 1, …, A − 1)
        else:
            inside[:, ks] = ins
    if not exclusive:
        return inside
    multi = inside.sum(axis=1) > 1
    if not np.any(multi):
        return inside
    rows = np.flatnonzero(multi)
    sub = pts[rows]
    cost = np.full((len(rows), A), np.inf)
    for k, area in enumerate(areas):
        # Range mismatch dominates; then the nearest area; then the bisector's angular offset.
        near = area.near_range_m if np.isfinite(area.near_range_m) else 1e3
        off = np.abs(area.angular_offsets(sub))
        c = _range_miss(sub, area, range_tolerance) * 1e6 + near * 1e2 + off - 1e-6 * area.confidence
        cost[:, k] = np.where(inside[rows, k], c, np.inf)
    best = np.argmin(cost, axis=1)
    inside[rows] = False
    inside[rows, best] = True
    return inside


def _range_miss(points_scan: FloatArray, area: BoundingArea, tolerance: float) -> FloatArray:
    """``(N,)`` how far each point's range about the apex lies outside ``[near_lo·(1−tol), near_hi·(1+tol)]``
    (an unknown bound: no limit), relative to the point's range."""
    d = np.asarray(points_scan, dtype=np.float64).reshape(-1, 2) - area.apex[None, :]
    r = np.hypot(d[:, 0], d[:, 1])
    lo = area.near_range_lo * (1.0 - tolerance) if np.isfinite(area.near_range_lo) else 0.0
    hi = area.near_range_hi * (1.0 + tolerance) if np.isfinite(area.near_range_hi) else np.inf
    return (np.maximum(lo - r, 0.0) + np.maximum(r - hi, 0.0)) / np.maximum(r, 0.1)


def range_deviation(points_scan: FloatArray, area: BoundingArea) -> FloatArray:
    """``(N,)`` how far each point's range about the area's apex lies outside the range its bottom edge
    gives (``[near_lo, near_hi]``), relative to the point's range (0 inside; ``nan`` when the bottom edge
    gives no range: cut by the border, or at or above the horizon)."""
    if not area.bottom_reliable or not np.isfinite(area.near_range_lo):
        return np.full(len(np.asarray(points_scan).reshape(-1, 2)), np.nan)
    return _range_miss(points_scan, area, 0.0)


def contest_by_range(points_scan: FloatArray, areas: Sequence[BoundingArea], member: NDArray[np.bool_],
                     slack: float) -> NDArray[np.bool_]:
    """Points inside several areas' wedges go only to the areas whose bottom-edge range explains them:
    an area loses a point whose range deviates from its own by more than ``slack`` (relative) beyond
    the best-explaining area's (:func:`range_deviation`). A table's leg in front of a chair seen behind
    it stays the table's; areas whose bottom edge gives no range keep their points. ``member``:
    ``(N, A)`` as :func:`assign_points` without ``exclusive``; returns a copy."""
    out = np.array(member, dtype=bool, copy=True)
    if out.ndim != 2 or out.shape[1] < 2:
        return out  # fewer than two areas: no point is shared
    multi = np.flatnonzero(out.sum(axis=1) > 1)
    if len(multi) == 0:
        return out
    sub = np.asarray(points_scan, dtype=np.float64).reshape(-1, 2)[multi]
    dev = np.column_stack([range_deviation(sub, a) for a in areas])
    dev = np.where(out[multi], dev, np.nan)  # nan: no range, or not a member: never loses
    best = np.min(np.where(np.isnan(dev), np.inf, dev), axis=1)
    out[multi] &= ~(dev > best[:, None] + slack)
    return out
