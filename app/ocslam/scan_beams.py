"""One LIDAR scan as the improved fusion reads it: its points, and every beam that says something.

A beam with a return in range gives a point (islands, ownership); a beam with no return says the
space along it is free up to the range limit; both are *known* beams, used for free-space, occlusion
and negative-evidence tests, about the scan origin and about the wedges' apex (the camera's centre on
the LIDAR plane). All in ``base_scan`` (2D, metres).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from app.ocslam.messages import LaserScan

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class ScanBeams:
    """``ranges (N,)`` all beams as given; ``valid (N,)`` a return within ``[range_min, range_max]``;
    ``points (M, 2)`` the valid returns; ``bearing_scan``/``range_scan`` ``(K,)`` the known beams about
    the scan origin (``inf``: no return); ``bearing_apex``/``range_apex`` ``(K,)`` the same beams about
    the apex (a beam with no return ends 1 km away)."""

    ranges: FloatArray
    valid: NDArray[np.bool_]
    points: FloatArray
    bearing_scan: FloatArray
    range_scan: FloatArray
    bearing_apex: FloatArray
    range_apex: FloatArray


def scan_beams(scan: LaserScan, angles: FloatArray, cos_a: FloatArray, sin_a: FloatArray, apex: FloatArray) -> ScanBeams:
    """``scan``'s :class:`ScanBeams`. ``angles``, ``cos_a``, ``sin_a``: ``(N,)`` its beam angles and their
    cosines and sines; ``apex``: ``(2,)`` the wedges' apex in ``base_scan``."""
    ranges = np.asarray(scan.ranges, dtype=np.float64).reshape(-1)
    with np.errstate(invalid="ignore"):
        finite = np.isfinite(ranges)
        valid = finite & (ranges >= scan.range_min) & (ranges <= scan.range_max)
        no_return = np.isposinf(ranges) | (finite & (ranges > scan.range_max))
    known = valid | no_return
    beam_b_scan = angles[known]
    beam_r_scan = np.where(valid[known], ranges[known], np.inf)
    r_valid = ranges[valid]
    pts = np.empty((len(r_valid), 2))
    np.multiply(r_valid, cos_a[valid], out=pts[:, 0])
    np.multiply(r_valid, sin_a[valid], out=pts[:, 1])
    hit = np.isfinite(beam_r_scan)
    far = np.where(hit, beam_r_scan, 1e3)
    ex = far * cos_a[known] - apex[0]
    ey = far * sin_a[known] - apex[1]
    return ScanBeams(ranges, valid, pts, beam_b_scan, beam_r_scan, np.arctan2(ey, ex), np.where(hit, np.hypot(ex, ey), np.inf))
