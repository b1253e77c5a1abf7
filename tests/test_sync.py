"""Time synchronisation: pose interpolation and scan re-projection (known answers)."""

from __future__ import annotations

import numpy as np
import pytest

from app.ocslam.messages import LaserScan
from app.ocslam.se2 import Pose2
from app.ocslam.sync import PoseBuffer, ScanBuffer, reproject_scan


def circle_scan(r: float, stamp: float = 0.0, n: int = 360) -> LaserScan:
    return LaserScan(stamp, -np.pi, 2 * np.pi / n, 0.12, 3.5, np.full(n, r))


def test_pose_buffer_interpolates_and_clamps() -> None:
    b = PoseBuffer()
    b.add(0.0, Pose2(0, 0, 0))
    b.add(1.0, Pose2(1, 2, 0.5))
    b.add(0.5, Pose2(9, 9, 9))  # out of order: ignored
    p = b.at(0.5)
    assert (p.x, p.y, p.yaw) == pytest.approx((0.5, 1.0, 0.25))
    assert b.at(5.0).x == pytest.approx(1.0)
    with pytest.raises(LookupError):
        PoseBuffer().at(0.0)


def test_scan_buffer_nearest_within_tolerance() -> None:
    b = ScanBuffer()
    for t in (0.0, 0.2, 0.4):
        b.add(circle_scan(1.0, t))
    assert b.nearest(0.29, 0.1).stamp == 0.2
    assert b.nearest(0.9, 0.1) is None


def test_scan_buffer_gap_equal_to_tolerance_survives_rounding() -> None:
    """A camera stamped half a LIDAR period after a scan: 0.30000000000000004 - 0.2 > 0.1 in floats."""
    b = ScanBuffer()
    b.add(circle_scan(1.0, 0.2))
    image_stamp = 0.1 + 0.2  # 0.30000000000000004, as the sim's clock accumulates it
    assert abs(image_stamp - 0.2) > 0.1
    assert b.nearest(image_stamp, 0.1).stamp == 0.2
    assert b.nearest(0.2 + 0.1 + 1e-3, 0.1) is None


def test_reproject_pure_rotation_shifts_beams() -> None:
    """The robot turned +10° since the scan: a return that was at 0° is now at −10°."""
    ranges = np.full(360, np.inf)
    ranges[180] = 2.0  # beam 180 points at 0 rad (angle_min = −π)
    scan = LaserScan(0.0, -np.pi, np.deg2rad(1.0), 0.12, 3.5, ranges)
    T_now_then = Pose2(0, 0, np.deg2rad(10)).inverse()  # pose at scan time, in the frame now
    out = reproject_scan(scan, Pose2(-0.03, 0, 0), T_now_then, stamp=0.1)
    assert out.stamp == 0.1
    hit = np.flatnonzero(np.isfinite(out.ranges))
    assert list(hit) == [170]
    # rotating about base (not the LIDAR) moves the LIDAR by a few mm: the range changes slightly
    assert out.ranges[170] == pytest.approx(2.0, abs=0.01)


def test_reproject_translation_shortens_ranges_ahead() -> None:
    scan = circle_scan(2.0)
    out = reproject_scan(scan, Pose2(), Pose2(-0.5, 0, 0), stamp=0.2)  # moved 0.5 m forward since
    assert out.ranges[180] == pytest.approx(1.5, abs=1e-6)  # ahead
    assert out.ranges[0] == pytest.approx(2.5, abs=0.02)  # behind
