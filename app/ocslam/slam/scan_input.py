"""A ``LaserScan`` as SLAM takes it: validation (bad scans are named, not raised) and the scan's geometry.

- :func:`check_scan` names why a scan cannot be used (NaN or negative finite ranges, non-finite or
  non-increasing stamps, a changed beam count, …) or returns None.
- :func:`scan_geometry` turns the ranges into returns and beam ends in the base frame. ``inf`` and
  max-range readings are *no return*: they clear free space (:func:`clear_ranges`) and mark nothing;
  ``-inf`` (REP-117: closer than ``range_min``) is a beam with no usable return that clears nothing.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import minimum_filter1d

from app.ocslam.config import SlamConfig
from app.ocslam.messages import LaserScan
from app.ocslam.se2 import Pose2
from app.ocslam.slam.keyframes import KeyframeScan


def check_scan(scan: LaserScan, odom: NDArray[np.float64], last_stamp: float, beams: int | None) -> str | None:
    """Why ``scan`` (with the odometry ``(3,)`` at its stamp) cannot be used, or None. ``last_stamp``: the
    previous processed scan's stamp; ``beams``: its beam count (None: no scan yet)."""
    r = np.asarray(scan.ranges, dtype=np.float64).reshape(-1)
    if not math.isfinite(scan.stamp):
        return "nonfinite_stamp"
    if scan.stamp <= last_stamp:
        return "stamp_not_increasing"
    if not np.all(np.isfinite(odom)):
        return "nonfinite_odometry"
    if len(r) == 0:
        return "empty"
    if not (math.isfinite(scan.angle_min) and math.isfinite(scan.angle_increment)):
        return "bad_angles"
    if np.isnan(r).any():
        return "nan_range"
    if (np.isfinite(r) & (r < 0)).any():
        return "negative_range"  # -inf is REP-117's "too close to measure": a valid beam without a return
    if beams is not None and len(r) != beams:
        return "wrong_length"
    return None


def clear_ranges(r: NDArray[np.float64], hit: NDArray[np.bool_], increment: float, cfg: SlamConfig) -> NDArray[np.float64]:
    """``(N,)`` distance each no-return beam of ranges ``r`` ``(N,)`` clears: ``free_clear_range_m``, but
    where a return (``hit``) lies within ``±free_clear_dropout_window_deg`` the beam is a dropout on that
    surface (dark, glossy, grazing: a cheap LIDAR misses a third of its beams on some walls) rather than
    open space, and it clears only up to two cells before the nearest such return, never through the wall
    behind it. A scan covering the full circle wraps around."""
    n = len(r)
    clear = np.full(n, cfg.free_clear_range_m)
    inc = abs(increment)
    if cfg.free_clear_range_m <= 0 or cfg.free_clear_dropout_window_deg <= 0 or inc <= 0 or n < 2:
        return clear
    k = min(int(round(math.radians(cfg.free_clear_dropout_window_deg) / inc)), n // 2)
    full_circle = inc * n >= 2 * math.pi - 1.5 * inc
    # the nearest return within ±k beams of each beam (wrapping around a full circle)
    nb = minimum_filter1d(np.where(hit, r, np.inf), 2 * k + 1, mode="wrap" if full_circle else "constant", cval=np.inf)
    return np.minimum(clear, nb - 2.0 * cfg.resolution_m)


def scan_geometry(scan: LaserScan, cfg: SlamConfig, T_base_scan: Pose2) -> KeyframeScan:
    """Returns ``points`` ``(P, 2)`` and beam ``ends`` ``(E, 2)`` (with their ``hit`` flags) in the base
    frame; no-return beams end where :func:`clear_ranges` says, ``-inf`` beams are left out."""
    r = np.asarray(scan.ranges, dtype=np.float64).reshape(-1)
    a = scan.angles
    with np.errstate(invalid="ignore"):
        hit = np.isfinite(r) & (r >= scan.range_min) & (r < scan.range_max) & (r <= cfg.max_range_m)
    clear = clear_ranges(r, hit, float(scan.angle_increment), cfg)
    rr = np.where(hit, r, clear)
    ends_scan = np.stack([rr * np.cos(a), rr * np.sin(a)], axis=1)
    ends = T_base_scan.transform_points(ends_scan)
    # a beam with something closer than range_min (-inf, REP-117) clears nothing
    keep = hit | ((clear > 0) & ~(r < scan.range_min))
    return KeyframeScan(
        points=ends[hit],
        ends=ends[keep],
        hit=hit[keep],
        sensor=np.array([T_base_scan.x, T_base_scan.y]),
    )
