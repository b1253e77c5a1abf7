"""The Slam facade: bad scans are skipped and counted, the map survives them; save/load continues mapping."""

from __future__ import annotations

import dataclasses

import numpy as np

from app.ocslam.config import SlamConfig
from app.ocslam.messages import LaserScan
from app.ocslam.se2 import Pose2, wrap_angle
from app.ocslam.slam import Slam
from app.ocslam.slam.scan_input import clear_ranges, scan_geometry
from app.ocslam.slam.synthetic import room_world, simulate_scan

SEGS = room_world()


def _drive(slam, n, t0=0.0, start=(2.0, 2.0, 0.0), rng=None):
    rng = rng or np.random.default_rng(0)
    truth = []
    for i in range(n):
        p = Pose2(start[0] + 0.04 * i, start[1] + 0.01 * i, start[2] + 0.01 * i)
        truth.append(p.as_array())
        slam.process(simulate_scan(p, SEGS, stamp=t0 + 0.2 * i, noise_std=0.005, rng=rng), p)
    return np.array(truth)


def _bad(scan: LaserScan, **kw) -> LaserScan:
    return dataclasses.replace(scan, **kw)


def test_bad_scans_are_skipped_and_counted():
    slam = Slam(SlamConfig())
    _drive(slam, 30)
    grid0 = slam.occupancy_grid()
    n0 = len(slam.trajectory()[0])
    kf0 = len(slam.keyframes)
    good = simulate_scan(Pose2(3.2, 2.3, 0.3), SEGS, stamp=100.0)
    r = good.ranges.copy()
    nan = r.copy()
    nan[5] = np.nan
    neg = r.copy()
    neg[7] = -1.0
    odo = Pose2(3.2, 2.3, 0.3)
    assert not slam.process(_bad(good, ranges=nan), odo)
    assert not slam.process(_bad(good, ranges=neg), odo)
    assert not slam.process(_bad(good, ranges=np.zeros(0)), odo)
    assert not slam.process(_bad(good, ranges=r[:100]), odo)
    assert not slam.process(_bad(good, stamp=float("nan")), odo)
    assert not slam.process(_bad(good, stamp=1.0), odo)  # older than the last processed scan
    assert not slam.process(good, Pose2(float("inf"), 0.0, 0.0))
    assert not slam.process(_bad(good, ranges=np.full_like(r, np.inf)), odo)  # nothing in range
    assert dict(slam.skipped) == {
        "nan_range": 1,
        "negative_range": 1,
        "empty": 1,
        "wrong_length": 1,
        "nonfinite_stamp": 1,
        "stamp_not_increasing": 1,
        "nonfinite_odometry": 1,
        "too_few_returns": 1,
    }
    # only the all-inf scan (a valid scan with no returns) extends the trajectory, on odometry
    assert len(slam.trajectory()[0]) == n0 + 1
    assert len(slam.keyframes) == kf0
    grid1 = slam.occupancy_grid()
    assert np.array_equal(grid0.data, grid1.data)
    # and mapping goes on afterwards
    _drive(slam, 10, t0=200.0, start=(3.3, 2.3, 0.3))
    assert len(slam.keyframes) > kf0
    assert np.isfinite(slam.trajectory()[1]).all()


def test_tracking_on_exact_odometry_and_outputs():
    slam = Slam(SlamConfig())
    truth = _drive(slam, 40)
    st, est = slam.trajectory()
    assert len(st) == 40
    assert np.abs(est[:, :2] - truth[:, :2]).max() < 0.03
    g = slam.pose_graph()
    assert g.nodes.shape[1] == 3 and len(g.stamps) == len(g.nodes)
    assert g.edges.shape == (len(g.nodes) - 1, 2) and not g.is_loop.any()
    k = slam.keyframe_at(st[-1])
    assert k == len(g.nodes) - 1 or k == len(g.nodes) - 2
    assert np.allclose(slam.keyframe_pose(0).as_array(), g.nodes[0])
    grid = slam.occupancy_grid()
    assert grid.frame_id == "map" and (grid.data == 100).sum() + (grid.data > 65).sum() > 50


def test_state_dict_round_trip_continues_mapping():
    cfg = SlamConfig()
    a = Slam(cfg, Pose2(0.05, 0.0, 0.0))
    _drive(a, 25)
    d = a.state_dict()
    assert all(isinstance(v, (np.ndarray, int, float, str, dict, list)) for v in d.values())
    b = Slam.from_state_dict(cfg, d)
    assert np.array_equal(a.trajectory()[1], b.trajectory()[1])
    assert np.array_equal(a.pose_graph().edges, b.pose_graph().edges)
    assert b.T_base_scan == a.T_base_scan
    assert np.array_equal(a.occupancy_grid().data, b.occupancy_grid().data)
    # both continue identically
    rng1, rng2 = np.random.default_rng(5), np.random.default_rng(5)
    _drive(a, 10, t0=50.0, start=(3.0, 2.25, 0.25), rng=rng1)
    _drive(b, 10, t0=50.0, start=(3.0, 2.25, 0.25), rng=rng2)
    assert np.allclose(a.trajectory()[1], b.trajectory()[1])


def test_disabled_slam_follows_odometry():
    slam = Slam(SlamConfig(enabled=False))
    truth = _drive(slam, 5)
    assert np.allclose(slam.trajectory()[1], truth)
    assert np.allclose(slam.T_map_odom.as_array(), 0.0, atol=1e-12)


def test_heading_comes_from_the_scan_when_odometry_jitters_in_a_turn():
    """A turn in place at 46°/s whose odometry increments are off by ±60 % (timing jitter between the
    odometry and the laser, as in the ACES log): the scan-to-map heading must follow the scans, not the
    prediction. With the prior strong in heading (σ 0.1 rad) the estimate was pulled toward the
    odometry: mean 0.64°, worst 2.5° per step."""
    rng = np.random.default_rng(0)
    slam = Slam(SlamConfig())
    yaw = oyaw = 0.0
    truth = []
    for i in range(80):
        d = 0.08 if i > 5 else 0.0
        yaw += d
        oyaw += d * rng.uniform(0.4, 1.6)
        slam.process(simulate_scan(Pose2(2.5, 2.0, yaw), SEGS, stamp=0.1 * i, noise_std=0.005, rng=rng), Pose2(2.5, 2.0, oyaw))
        truth.append(yaw)
    _, est = slam.trajectory()
    step_err = np.degrees(np.abs(wrap_angle(np.diff(est[:, 2]) - np.diff(truth))))
    assert step_err.mean() < 0.25
    assert step_err.max() < 1.0


def test_too_close_beams_keep_the_scan_and_clear_nothing():
    """REP-117: ``-inf`` means "closer than range_min". Such a beam has no usable return, but the scan is
    valid (a robot brushing an obstacle used to lose every scan of the contact), and the beam must
    not clear free space where something stands in front of the sensor."""
    slam = Slam(SlamConfig())
    _drive(slam, 30)
    p = Pose2(3.2, 2.3, 0.3)
    good = simulate_scan(p, SEGS, stamp=100.0)
    r = good.ranges.copy()
    r[:40] = -np.inf
    n_before = len(slam.trajectory()[0])
    slam.process(_bad(good, ranges=r), p)
    assert "negative_range" not in slam.skipped
    assert len(slam.trajectory()[0]) == n_before + 1
    geo = scan_geometry(_bad(good, ranges=r), slam.cfg, slam.T_base_scan)
    assert len(geo.points) == np.count_nonzero(np.isfinite(r) & (r >= good.range_min) & (r < good.range_max))
    assert len(geo.ends) == len(r) - 40  # the -inf beams clear nothing


def test_a_dropout_on_a_wall_clears_only_up_to_the_wall():
    """No-return beams among returns from a wall 2 m away are dropouts (a cheap LIDAR misses beams on dark
    or glossy surfaces): they clear up to just before the wall, not 3 m through it. A no-return beam
    with no return near it (open space beyond the range) still clears ``free_clear_range_m``."""
    cfg = SlamConfig()
    slam = Slam(cfg)
    n = 360
    inc = 2 * np.pi / n
    r = np.full(n, np.inf)
    r[:90] = 2.0  # a wall in front of the first quarter of the beams
    r[40:43] = np.inf  # three dropouts on it
    hit = np.isfinite(r)
    clear = clear_ranges(r, hit, inc, cfg)
    assert np.all(clear[40:43] <= 2.0 - 2 * cfg.resolution_m + 1e-9)
    assert clear[200] == cfg.free_clear_range_m  # open space, no return within 5°
    assert clear[92] < 2.0 and clear[100] == cfg.free_clear_range_m  # next to the wall's end, then open
    # the circle wraps: beam n-1 is next to beam 0 (on the wall)
    assert clear[n - 1] < 2.0
    # the whole scan: the dropouts' ends stop short of the wall
    scan = simulate_scan(Pose2(2.0, 2.0, 0.0), SEGS, stamp=0.0)
    rr = scan.ranges.copy()
    rr[10:13] = np.inf
    geo = scan_geometry(dataclasses.replace(scan, ranges=rr), slam.cfg, slam.T_base_scan)
    assert len(geo.ends) == len(rr)
    assert np.all(np.hypot(*geo.ends[~geo.hit].T) < scan.range_max)
