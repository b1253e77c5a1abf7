"""Negative evidence on an object's points: parts of it seen *outside* its own box.

An object's evidence is the union of the LIDAR islands its boxes proposed, frame after frame. A
neighbour's points can join it from a viewpoint where the two line up (a stool behind a round table,
inside the table's wedge); from another viewpoint the same points stand clear of the table's box. A
point of the object's evidence that the LIDAR sees *now* (a return at its bearing and range), inside
the camera's image, while the object's own box in this frame does not cover its bearing, is a view that
says "not this object". :func:`seen_outside` finds those points; :class:`app.ocslam.evidence.ObjectEvidence`
counts them per voxel (``outside``), and the footprint ignores voxels seen outside more often than the
ratio ``consciousness.outside_ratio`` of their hits (:meth:`ObjectEvidence.trusted`).

All geometry is in ``base_scan`` after one transform; no per-point Python loop.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from app.ocslam.camera import CameraModel
from app.ocslam.projection import BoundingArea, camera_bound_bearings
from app.ocslam.se2 import Pose2, wrap_angle

FloatArray = NDArray[np.float64]


def lidar_sees(
    points_scan: FloatArray, ranges: FloatArray, angle_min: float, increment: float, tol_m: float | FloatArray
) -> NDArray[np.bool_]:
    """``(N, 2)`` points in ``base_scan`` → ``(N,)`` True where the scan has a return at the point: a beam
    within one increment of its bearing whose range is within ``tol_m`` (a float or ``(N,)``) of the
    point's (the surface there is seen now, not hidden behind something nearer). ``ranges``: ``(n,)`` the
    scan's ranges (NaN/inf: no return)."""
    p = np.asarray(points_scan, dtype=np.float64).reshape(-1, 2)
    n = len(ranges)
    if len(p) == 0 or n == 0 or not increment:
        return np.zeros(len(p), dtype=bool)
    r = np.hypot(p[:, 0], p[:, 1])
    b = np.arctan2(p[:, 1], p[:, 0])
    full = abs(increment) * n >= 2.0 * np.pi - 1e-6
    k = np.rint(wrap_angle(b - angle_min) / increment if full else (b - angle_min) / increment).astype(np.int64)
    seen = np.zeros(len(p), dtype=bool)
    with np.errstate(invalid="ignore"):
        for d in (-1, 0, 1):
            j = k + d
            if full:
                j %= n
                seen |= np.abs(ranges[j] - r) <= tol_m
            else:
                ok = (j >= 0) & (j < n)
                j = np.clip(j, 0, n - 1)
                seen |= ok & (np.abs(ranges[j] - r) <= tol_m)
    return seen


def seen_outside(
    points_map: FloatArray,
    weights: NDArray[np.float64] | NDArray[np.int64],
    T_map_scan: Pose2,
    area: BoundingArea,
    camera: CameraModel,
    ranges: FloatArray,
    angle_min: float,
    increment: float,
    max_range_m: float,
    margin_m: float = 0.05,
    margin_rel: float = 0.15,
    border_rad: float = math.radians(2.0),
) -> NDArray[np.bool_]:
    """``(N, 2)`` evidence points (``map``, ``(N,)`` ``weights``: their hits) of an object whose box this
    frame is ``area`` → ``(N,)`` True where the point is seen now (:func:`lidar_sees`), inside the image
    (``border_rad`` from its edges), within ``max_range_m`` of the apex, and outside the box's wedge by
    more than ``margin_m`` plus ``margin_rel`` of the box's width (a detector's box is not exact).

    The box must be the object's: if less than half of the object's visible evidence (by weight) lies
    inside it (a box of part of the object, or of a neighbour that was associated with it), it says
    nothing against any point and nothing is returned."""
    pm = np.asarray(points_map, dtype=np.float64).reshape(-1, 2)
    out = np.zeros(len(pm), dtype=bool)
    if len(pm) == 0:
        return out
    p = T_map_scan.inverse().transform_points(pm)
    b, r = camera.bearing_ranges_scan(p)
    b_right, b_left = camera_bound_bearings(camera)
    half_img = 0.5 * float(wrap_angle(b_left - b_right))
    mid_img = b_right + half_img
    in_image = (np.abs(wrap_angle(b - mid_img)) < half_img - border_rad) & (r <= max_range_m) & (r > 0.05)
    if not in_image.any():
        return out
    idx = np.flatnonzero(in_image)
    q = p[idx]
    tol = 0.04 + 0.02 * np.hypot(q[:, 0], q[:, 1])  # the voxel's size and the range noise
    seen = lidar_sees(q, np.asarray(ranges, dtype=np.float64), angle_min, increment, tol)
    if not seen.any():
        return out
    idx = idx[seen]
    half = float(area.half_angle)
    rel = np.abs(wrap_angle(b[idx] - (area.bearing_right + half)))  # from the wedge's middle
    w = np.asarray(weights, dtype=np.float64).reshape(-1)[idx]
    inside = rel <= half
    if float(w[inside].sum()) < 0.5 * float(w.sum()):
        return out
    margin = np.arctan2(margin_m, np.maximum(r[idx], 1e-6)) + 2.0 * margin_rel * half
    out[idx[rel > half + margin]] = True
    return out
