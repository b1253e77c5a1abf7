"""An object's footprint on the floor: an oriented rectangle (``Footprint``), and the geometry of point
sets it is made from (the minimum-area rectangle, nearest distances). All in the object frame (``map``).

Estimating an object's footprint from its evidence is :mod:`app.ocslam.footprint_estimate`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree
from shapely.geometry import Polygon

from app.ocslam.se2 import Pose2

FloatArray = NDArray[np.float64]
#: ``ndarray.min``/``max`` without their Python wrappers (the same reductions)
_MIN, _MAX = np.minimum.reduce, np.maximum.reduce


@dataclass
class Footprint:
    """An oriented rectangle: ``center`` (2,), ``yaw`` (rad, axis of ``size_x``), sizes (m)."""

    center: FloatArray
    yaw: float
    size_x: float
    size_y: float

    @property
    def corners(self) -> FloatArray:
        """(4, 2) counter-clockwise corners."""
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        hx, hy = self.size_x / 2.0, self.size_y / 2.0
        local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
        R = np.array([[c, -s], [s, c]])
        return local @ R.T + self.center[None, :]

    @property
    def polygon(self) -> Polygon:
        return Polygon(self.corners)

    @property
    def area(self) -> float:
        return float(self.size_x * self.size_y)

    @property
    def circumradius(self) -> float:
        """Half the diagonal (m): no point of the rectangle is farther from its centre."""
        return 0.5 * math.hypot(self.size_x, self.size_y)

    def contains(self, points: FloatArray, margin: float = 0.0) -> NDArray[np.bool_]:
        """``(N, 2)`` points → inside the rectangle grown by ``margin`` on every side."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2) - self.center[None, :]
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        lx = c * p[:, 0] + s * p[:, 1]
        ly = -s * p[:, 0] + c * p[:, 1]
        return (np.abs(lx) <= self.size_x / 2 + margin) & (np.abs(ly) <= self.size_y / 2 + margin)

    def contains_point(self, point: FloatArray, margin: float = 0.0) -> bool:
        """:meth:`contains` for one ``(2,)`` point (the same arithmetic, without arrays)."""
        px, py = float(point[0]) - float(self.center[0]), float(point[1]) - float(self.center[1])
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        lx = c * px + s * py
        ly = -s * px + c * py
        return bool(abs(lx) <= self.size_x / 2 + margin and abs(ly) <= self.size_y / 2 + margin)

    def nearest_distance(self, point: FloatArray) -> float:
        """Distance from a (2,) point to the rectangle (0 inside)."""
        p = np.asarray(point, dtype=np.float64) - self.center
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        lx, ly = c * p[0] + s * p[1], -s * p[0] + c * p[1]
        dx = max(abs(lx) - self.size_x / 2, 0.0)
        dy = max(abs(ly) - self.size_y / 2, 0.0)
        return float(np.hypot(dx, dy))

    def transformed(self, T: Pose2) -> Footprint:
        c = T.transform_points(self.center[None, :])[0]
        return Footprint(c, float(self.yaw + T.yaw), self.size_x, self.size_y)


def linspace(start: float, stop: float, num: int) -> FloatArray:
    """``np.linspace(start, stop, num)`` for ``num ≥ 2`` floats: the same values (``i·step + start``, the
    last exactly ``stop``) without its dtype handling, which costs more than the arithmetic here."""
    step = (stop - start) / (num - 1)
    if step == 0:
        y = np.arange(num, dtype=np.float64) / (num - 1) * (stop - start)
    else:
        y = np.arange(num, dtype=np.float64) * step
    y += start
    y[-1] = stop
    return y


def nearest_distances(a: FloatArray, b: FloatArray) -> FloatArray:
    """``(N,)`` distance from each of ``(N, 2)`` points to the nearest of ``(M, 2)`` points (M ≥ 1):
    all pairs for small sets, a KD-tree for large ones."""
    if len(a) * len(b) <= 4096:
        dx = a[:, 0][:, None] - b[:, 0][None, :]
        dy = a[:, 1][:, None] - b[:, 1][None, :]
        return np.sqrt((dx * dx + dy * dy).min(axis=1))
    return np.asarray(cKDTree(b).query(a, k=1)[0], dtype=np.float64)


def _hull_angles(p: FloatArray) -> FloatArray:
    """Orientations (mod 90°) of the convex hull's edges of ``(N, 2)`` points (N ≥ 3)."""
    hull = cv2.convexHull(p.astype(np.float32)).reshape(-1, 2).astype(np.float64)
    if len(hull) < 2:
        return np.array([0.0])
    e = np.empty_like(hull)  # each edge (np.roll(hull, -1) − hull, without its overhead)
    np.subtract(hull[1:], hull[:-1], out=e[:-1])
    np.subtract(hull[0], hull[-1], out=e[-1])
    e = e[np.hypot(e[:, 0], e[:, 1]) > 1e-6]
    if len(e) == 0:
        return np.array([0.0])
    a = (np.arctan2(e[:, 1], e[:, 0]) % (np.pi / 2)).round(9)
    a.sort()
    return a[np.concatenate(([True], a[1:] != a[:-1]))]  # np.unique's result, without its overhead


def min_area_rect(points: FloatArray) -> tuple[float, FloatArray, FloatArray]:
    """Enclosing rectangle of ``(N, 2)`` boundary points, oriented by the closeness criterion.

    Candidate orientations are the convex hull's edge directions (so the result turns with the points).
    The LIDAR sees an object's outline, so its points lie on the rectangle's sides: the orientation
    that brings the points closest to their nearest side wins (Zhang et al., "Efficient L-shape
    fitting for vehicle detection using laser scanners", 2017): score = Σ 1 / max(d_i, 1 cm). Unlike
    a minimum-area rectangle it is not fooled by the diagonal of an L (three legs of a table, two
    faces of an armchair). Clusters smaller than 0.5 m (a pair of legs, a curved surface) take the
    minimum-area orientation instead. Returns ``(theta, lo (2,), hi (2,))``: the first axis angle and
    the points' extents along ``e1 = (cos θ, sin θ)`` and ``e2 = (−sin θ, cos θ)``.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    n = len(p)
    if n >= 3:
        q = p - p.sum(axis=0) / n  # p.mean(axis=0), without its overhead
        thetas = _hull_angles(q)
        k = len(thetas)
        cs, sn = np.cos(thetas), np.sin(thetas)
        # both coordinates along every candidate's axes at once: rows ``a = x·cos + y·sin`` (K), then
        # ``b = x·(−sin) + y·cos`` (K; ``y·cos − x·sin`` in the same roundings)
        ab = q[:, 0][None, :] * np.concatenate([cs, -sn])[:, None] + q[:, 1][None, :] * np.concatenate([sn, cs])[:, None]
        ab_lo, ab_hi = _MIN(ab, axis=1, keepdims=True), _MAX(ab, axis=1, keepdims=True)
        ext = ab_hi - ab_lo
        area = (ext[:k] * ext[k:])[:, 0]
        q_ext = _MAX(q, axis=0) - _MIN(q, axis=0)
        if max(float(q_ext[0]), float(q_ext[1])) < 0.5:
            # a small cluster: the outline says little, the minimum-area rectangle follows its line
            th = float(thetas[int(np.argmin(area))])
        else:
            d = np.minimum(ab - ab_lo, ab_hi - ab)  # each point's distance to the nearer side, per axis
            score = np.add.reduce(1.0 / np.maximum(np.minimum(d[:k], d[k:]), 0.01), axis=1)
            best = np.flatnonzero(score >= score.max() * (1.0 - 1e-6))  # ties: the smaller area
            th = float(thetas[best[np.argmin(area[best])]])
    elif n == 2:
        d = p[1] - p[0]
        th = float(np.arctan2(d[1], d[0]) % (np.pi / 2))
    else:
        th = 0.0
    c, s = np.cos(th), np.sin(th)
    # (a, b) = (x·c + y·s, x·(−s) + y·c) per point (``−x·s + y·c`` in the same roundings)
    ab1 = p[:, 0:1] * np.array([c, -s]) + p[:, 1:2] * np.array([s, c])
    return th, _MIN(ab1, axis=0), _MAX(ab1, axis=0)


def rect_corners_near(points: FloatArray, rect: tuple[float, FloatArray, FloatArray]) -> tuple[FloatArray, NDArray[np.int64]]:
    """How far ``(N, 2)`` points lie from the nearest corner of a rectangle ``rect`` (:func:`min_area_rect`'s
    ``(theta, lo, hi)``), and which corner that is: ``(dist (N,), corner (N,))``, the corner numbered
    ``2·[nearer hi along e1] + [nearer hi along e2]`` (0…3)."""
    th, lo, hi = rect
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    c, s = float(np.cos(th)), float(np.sin(th))
    a = p[:, 0] * c + p[:, 1] * s
    b = -p[:, 0] * s + p[:, 1] * c
    a_lo, a_hi, b_lo, b_hi = np.abs(a - lo[0]), np.abs(a - hi[0]), np.abs(b - lo[1]), np.abs(b - hi[1])
    dist = np.hypot(np.minimum(a_lo, a_hi), np.minimum(b_lo, b_hi))
    return dist, 2 * (a_hi < a_lo).astype(np.int64) + (b_hi < b_lo).astype(np.int64)
