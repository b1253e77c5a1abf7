"""Small geometric predicates the association and the collision rules share: angles, footprint overlap, point-set
distance, whether extents fit one instance of a class, rays (``map`` frame throughout)."""

from __future__ import annotations

import math

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray

from app.ocslam.classes import ClassPrior
from app.ocslam.footprint import Footprint, min_area_rect, nearest_distances

FloatArray = NDArray[np.float64]


def angle_wrap(a: ArrayLike) -> NDArray[np.float64]:
    """Angles (rad, any shape) wrapped into ``[-π, π)``."""
    return np.asarray((np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi)


def overlap_fraction(a: Footprint, b: Footprint) -> float:
    """Intersection area over the smaller footprint's area."""
    # rectangles whose circumcircles are apart do not overlap (most pairs of a map): no polygons
    if math.hypot(float(a.center[0] - b.center[0]), float(a.center[1] - b.center[1])) > a.circumradius + b.circumradius + 1e-9:
        return 0.0
    pa, pb = a.polygon, b.polygon
    inter = shapely.area(shapely.intersection(pa, pb))
    small = max(min(pa.area, pb.area), 1e-9)
    return float(inter / small)


def min_distance(a: FloatArray, b: FloatArray) -> float:
    """Smallest distance between two ``(N, 2)`` / ``(M, 2)`` point sets (inf if either is empty)."""
    if len(a) == 0 or len(b) == 0:
        return math.inf
    return float(nearest_distances(a, b).min())


def fits_instance(pc: ClassPrior, extent_a: float, extent_b: float, typical: bool) -> bool:
    """True if extents fit one object of the class: one of its typical shapes (25 % tolerance) with
    ``typical``, else its largest instance (10 %)."""
    if typical:
        return pc.fits_typical(extent_a, extent_b, tolerance=0.25)
    return pc.fits(extent_a, extent_b, tolerance=0.1)


def contiguous(a: FloatArray, b: FloatArray, pc: ClassPrior, gap_m: float, typical: bool = False) -> bool:
    """True if two point sets lie within ``gap_m`` and together fit one object of the class (one of
    its typical shapes with ``typical``: :func:`fits_instance`)."""
    if len(a) == 0 or len(b) == 0 or min_distance(a, b) > gap_m:
        return False
    _th, lo, hi = min_area_rect(np.vstack([a, b]))
    d = hi - lo
    return fits_instance(pc, float(d[0]), float(d[1]), typical)


def along_ray_close(origin: FloatArray, a: FloatArray, b: FloatArray, thr: float, rel: float = 0.25) -> bool:
    """True if ``b`` is within ``thr`` of ``a`` across the line of sight from ``origin``, and within
    ``max(thr, rel·range)`` along it (the uncertainty of ground-plane ranging)."""
    v = a - origin
    r = float(np.hypot(v[0], v[1]))
    if r < 1e-6:
        return float(np.hypot(*(b - a))) < thr
    u = v / r
    d = b - a
    along = abs(float(d @ u))
    across = abs(float(d[0] * u[1] - d[1] * u[0]))
    return across < thr and along < max(thr, rel * r)
