"""Time synchronisation of images, scans and poses (the original used the latest of each, unsynced).

Improved mode takes the scan nearest the image stamp and the pose interpolated at it, then moves the
scan's points into the robot frame at the image stamp, so boxes and points describe the same instant.

Example:
    >>> poses = PoseBuffer()
    >>> poses.add(0.0, Pose2(0, 0, 0)); poses.add(1.0, Pose2(1, 0, 0))
    >>> poses.at(0.25).x
    0.25
"""

from __future__ import annotations

from collections import deque
from dataclasses import replace

import numpy as np

from app.ocslam import se2
from app.ocslam.messages import LaserScan
from app.ocslam.se2 import Pose2

#: Slack added to stamp comparisons (sim stamps accumulate float rounding of their periods).
STAMP_SLACK_S = 1e-6


class PoseBuffer:
    """A bounded, time-ordered buffer of stamped poses with interpolation."""

    def __init__(self, maxlen: int = 2000) -> None:
        self._stamps: deque[float] = deque(maxlen=maxlen)
        self._poses: deque[tuple[float, float, float]] = deque(maxlen=maxlen)

    def __len__(self) -> int:
        return len(self._stamps)

    def clear(self) -> None:
        self._stamps.clear()
        self._poses.clear()

    def add(self, stamp: float, pose: Pose2) -> None:
        if self._stamps and stamp < self._stamps[-1]:
            return  # out of order: ignore (never rewind time)
        if self._stamps and stamp == self._stamps[-1]:
            self._poses[-1] = (pose.x, pose.y, pose.yaw)
            return
        self._stamps.append(stamp)
        self._poses.append((pose.x, pose.y, pose.yaw))

    def latest(self) -> tuple[float, Pose2] | None:
        if not self._stamps:
            return None
        return self._stamps[-1], Pose2(*self._poses[-1])

    def at(self, stamp: float) -> Pose2:
        """Pose interpolated at ``stamp`` (clamped to the buffer's span)."""
        if not self._stamps:
            raise LookupError("PoseBuffer.at: no poses yet")
        stamps = np.fromiter(self._stamps, dtype=np.float64, count=len(self._stamps))
        i = int(np.searchsorted(stamps, stamp))
        lo, hi = max(0, i - 1), min(len(stamps), i + 1)
        window = np.array([self._poses[k] for k in range(lo, hi)])
        return Pose2.from_array(se2.interpolate(stamp, stamps[lo:hi], window))


class ScanBuffer:
    """The last few scans, to find the one nearest an image stamp."""

    def __init__(self, maxlen: int = 10) -> None:
        self._scans: deque[LaserScan] = deque(maxlen=maxlen)

    def add(self, scan: LaserScan) -> None:
        self._scans.append(scan)

    def latest(self) -> LaserScan | None:
        return self._scans[-1] if self._scans else None

    def nearest(self, stamp: float, tolerance_s: float) -> LaserScan | None:
        """The scan whose stamp is nearest ``stamp``, if within ``tolerance_s``.

        Stamps are sums of float periods (``0.1 + 0.2 != 0.3``), so a gap equal to the tolerance is
        compared with a microsecond of slack: a camera half a LIDAR period off its scans must not lose
        every other frame to rounding.
        """
        if not self._scans:
            return None
        best = min(self._scans, key=lambda s: abs(s.stamp - stamp))
        return best if abs(best.stamp - stamp) <= tolerance_s + STAMP_SLACK_S else None

    def clear(self) -> None:
        self._scans.clear()


def reproject_scan(scan: LaserScan, T_base_scan: Pose2, T_now_then: Pose2, stamp: float) -> LaserScan:
    """Move a scan's returns into the sensor frame at another instant.

    ``T_now_then`` is the robot (``base_footprint``) pose at the scan's stamp expressed in the robot
    frame at ``stamp``. Points are re-binned into the same beam layout (nearest return per beam);
    beams left without a return become ``inf``.
    """
    pts = scan.points()
    T = T_base_scan.inverse() @ T_now_then @ T_base_scan
    return replace(scan, ranges=bin_to_beams(scan, T.transform_points(pts) if len(pts) else pts), stamp=stamp)


def bin_to_beams(scan: LaserScan, points: np.ndarray) -> np.ndarray:
    """Ranges in ``scan``'s beam layout for ``(N, 2)`` points in its sensor plane: the nearest point per
    beam, ``inf`` (no return) for beams that receive none."""
    n = len(scan.ranges)
    out = np.full(n, np.inf)
    if len(points) and n:
        r = np.hypot(points[:, 0], points[:, 1])
        a = np.arctan2(points[:, 1], points[:, 0])
        full_circle = abs(scan.angle_increment) * n >= 2 * np.pi - 1e-6
        d = np.mod(a - scan.angle_min, 2 * np.pi) if full_circle else se2.wrap_angle(a - scan.angle_min)
        idx = np.rint(d / scan.angle_increment).astype(np.int64)
        if full_circle:
            idx %= n
        ok = (idx >= 0) & (idx < n)
        np.minimum.at(out, idx[ok], r[ok])
    return out
