"""Synthetic 2D worlds of wall segments and exact LIDAR scans of them (for tests, docs and demos).

``segments`` are ``(S, 4)`` rows ``x0 y0 x1 y1`` in the world frame. :func:`simulate_scan` intersects every
beam with every segment (vectorised), so a scan is exact up to the added range noise.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from app.ocslam.messages import LaserScan
from app.ocslam.se2 import Pose2


def box(x0: float, y0: float, x1: float, y1: float) -> NDArray[np.float64]:
    """``(4, 4)`` segments of an axis-aligned rectangle."""
    return np.array([[x0, y0, x1, y0], [x1, y0, x1, y1], [x1, y1, x0, y1], [x0, y1, x0, y0]], np.float64)


def room_world() -> NDArray[np.float64]:
    """An irregular 10 m × 8 m room with an inner wall and a few boxes (distinctive for matching)."""
    segs = [
        box(0.0, 0.0, 10.0, 8.0),
        np.array([[4.0, 0.0, 4.0, 3.0], [6.5, 8.0, 6.5, 5.5], [0.0, 5.0, 1.5, 5.0]]),
        box(2.0, 6.0, 2.6, 6.5),
        box(7.5, 1.5, 8.3, 2.0),
        box(5.0, 4.0, 5.4, 4.4),
        np.array([[8.5, 6.5, 9.5, 7.3]]),
    ]
    return np.vstack(segs)


def simulate_scan(
    T_world_scan: Pose2,
    segments: NDArray[np.float64],
    stamp: float = 0.0,
    n_beams: int = 360,
    angle_min: float = -np.pi,
    fov: float = 2 * np.pi,
    range_max: float = 3.5,
    noise_std: float = 0.0,
    rng: np.random.Generator | None = None,
) -> LaserScan:
    """Scan of ``segments`` from ``T_world_scan``: nearest intersection per beam, ``inf`` beyond ``range_max``."""
    inc = fov / n_beams
    ang = angle_min + inc * np.arange(n_beams) + T_world_scan.yaw
    d = np.stack([np.cos(ang), np.sin(ang)], axis=1)  # (B, 2)
    p = np.array([T_world_scan.x, T_world_scan.y])
    a = segments[:, :2]
    e = segments[:, 2:] - a  # (S, 2)
    # solve p + t d = a + u e
    den = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]  # (B, S)
    ap = a[None, :, :] - p[None, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ap[..., 0] * e[None, :, 1] - ap[..., 1] * e[None, :, 0]) / den
        u = (ap[..., 0] * d[:, None, 1] - ap[..., 1] * d[:, None, 0]) / den
    ok = (np.abs(den) > 1e-12) & (t > 1e-9) & (u >= 0) & (u <= 1)
    t = np.where(ok, t, np.inf).min(axis=1)
    if noise_std > 0:
        rng = rng or np.random.default_rng()
        t = t + rng.normal(0.0, noise_std, size=t.shape)
    t = np.where(t <= range_max, t, np.inf)
    return LaserScan(stamp=stamp, angle_min=angle_min, angle_increment=inc, range_min=0.05, range_max=range_max, ranges=t)
