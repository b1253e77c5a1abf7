"""A synthetic loop with drifting odometry closes, and the corrected trajectory matches the truth."""

from __future__ import annotations

import numpy as np

from app.ocslam.config import SlamConfig
from app.ocslam.se2 import Pose2, between, compose
from app.ocslam.slam import Slam, ate_rmse
from app.ocslam.slam.synthetic import box, simulate_scan


def ring_world() -> np.ndarray:
    """A 14 m × 10 m ring corridor around a central block, with distinct bumps along the walls."""
    segs = [box(0.0, 0.0, 14.0, 10.0), box(3.0, 3.0, 11.0, 7.0)]
    bumps = [
        box(2.0, 0.0, 2.4, 0.5), box(6.0, 0.0, 6.8, 0.4), box(10.5, 0.0, 10.8, 0.7),
        box(13.4, 2.0, 14.0, 2.3), box(13.6, 6.5, 14.0, 7.5),
        box(9.0, 9.5, 9.5, 10.0), box(4.0, 9.3, 4.2, 10.0), box(0.0, 7.5, 0.6, 7.9), box(0.0, 3.0, 0.3, 4.2),
        box(5.0, 2.6, 5.5, 3.0), box(8.5, 7.0, 9.2, 7.4), box(11.0, 4.5, 11.4, 5.0), box(2.6, 5.5, 3.0, 6.0),
    ]
    return np.vstack(segs + bumps)


def square_path(step=0.15):
    """Poses around the ring (counter-clockwise), 1.25 laps, turning on the spot at the corners."""
    corners = [(1.5, 1.5), (12.5, 1.5), (12.5, 8.5), (1.5, 8.5)]
    poses = []
    for lap in range(2):
        for k in range(4):
            a, b = np.array(corners[k]), np.array(corners[(k + 1) % 4])
            yaw = np.arctan2(*(b - a)[::-1])
            if poses:  # turn in place
                y0 = poses[-1][2]
                dy = (yaw - y0 + np.pi) % (2 * np.pi) - np.pi
                for f in np.linspace(0, 1, 8)[1:]:
                    poses.append((a[0], a[1], y0 + f * dy))
            n = int(np.linalg.norm(b - a) / step)
            for f in np.arange(n) / n:
                p = a + f * (b - a)
                poses.append((p[0], p[1], yaw))
            if lap == 1 and k == 1:
                return np.array(poses)
    return np.array(poses)


def test_square_loop_closes():
    world = ring_world()
    truth = square_path()
    rng = np.random.default_rng(7)
    # odometry: true increments with a yaw drift (1.5 °/m) and 2 % scale error, plus noise
    odom = [truth[0].copy()]
    for a, b in zip(truth[:-1], truth[1:]):
        d = between(a, b)
        dist = np.hypot(d[0], d[1])
        d = d * np.array([1.02, 1.02, 1.0]) + np.array([0, 0, np.radians(1.5) * dist])
        d = d + rng.normal(0, [0.002, 0.002, 0.002])
        odom.append(compose(odom[-1], d))
    odom = np.array(odom)
    cfg = SlamConfig(max_range_m=8.0)
    slam = Slam(cfg)
    for i, (t, o) in enumerate(zip(truth, odom)):
        scan = simulate_scan(Pose2(*t), world, stamp=0.2 * i, n_beams=360, range_max=8.0, noise_std=0.01, rng=rng)
        slam.process(scan, Pose2(*o))
    stamps, est = slam.trajectory()
    assert len(est) == len(truth)
    g = slam.pose_graph()
    assert g.is_loop.sum() >= 1, "no loop closure found"
    assert slam.correction_count >= 1
    # the map frame is the odometry frame at start, which here equals the world frame
    ate_slam = ate_rmse(est, truth)
    ate_odom = ate_rmse(odom, truth)
    assert ate_odom > 0.4
    assert ate_slam < 0.08, (ate_slam, ate_odom)
    # the map -> odom correction maps the last odometry pose onto the last estimate
    last = (slam.T_map_odom @ Pose2(*odom[-1])).as_array()
    assert np.allclose(last, est[-1], atol=1e-9)
    # pose_at interpolates between processed scans
    mid = slam.pose_at(0.5 * (stamps[10] + stamps[11])).as_array()
    assert np.hypot(*(mid[:2] - 0.5 * (est[10, :2] + est[11, :2]))) < 1e-9
