"""Differential-drive kinematics with known answers (paper §2.2, spec §3)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.ocslam.config import RobotConfig
from app.ocslam.messages import Twist, WheelEncoders
from app.ocslam.odometry import DiffDriveOdometry, clamp_twist, twist_to_wheel_rates, wheel_rates_to_twist

R = 0.033
L = 0.160


def drive(odom: DiffDriveOdometry, wl: float, wr: float, seconds: float, dt: float = 0.01, t0: float = 0.0):
    """Feed constant wheel rates; returns the last Odometry."""
    n = int(round(seconds / dt))
    dt = seconds / n
    left = right = 0.0
    msg = odom.update(WheelEncoders(t0, left, right))
    for k in range(1, n + 1):
        left += wl * dt
        right += wr * dt
        msg = odom.update(WheelEncoders(t0 + k * dt, left, right))
    return msg


def test_straight_line() -> None:
    odom = DiffDriveOdometry(RobotConfig())
    msg = drive(odom, 0.1 / R, 0.1 / R, 10.0)
    assert msg.T_odom_base.x == pytest.approx(1.0, abs=1e-9)
    assert msg.T_odom_base.y == pytest.approx(0.0, abs=1e-12)
    assert msg.linear_x == pytest.approx(0.1)
    assert odom.distance_m == pytest.approx(1.0)


def test_spin_in_place() -> None:
    odom = DiffDriveOdometry(RobotConfig())
    # ω = (ωr − ωl)·r/l = 1 rad/s  ->  ωr = −ωl = l/(2r)
    w = L / (2 * R)
    msg = drive(odom, -w, w, math.pi / 2, dt=math.pi / 2 / 1000)
    assert msg.T_odom_base.yaw == pytest.approx(math.pi / 2, abs=1e-9)
    assert math.hypot(msg.T_odom_base.x, msg.T_odom_base.y) < 1e-12
    assert msg.angular_z == pytest.approx(1.0)


def test_arc_quarter_circle() -> None:
    """v = 0.1 m/s, ω = 0.2 rad/s: radius 0.5 m; a quarter turn ends near (0.5, 0.5)."""
    cfg = RobotConfig()
    wl, wr = twist_to_wheel_rates(Twist(0.1, 0.2), cfg)
    msg = drive(odom := DiffDriveOdometry(cfg), wl, wr, (math.pi / 2) / 0.2, dt=0.001)
    assert msg.T_odom_base.yaw == pytest.approx(math.pi / 2, abs=1e-6)
    # the Euler step with the new heading has O(dt) error
    assert msg.T_odom_base.x == pytest.approx(0.5, abs=2e-3)
    assert msg.T_odom_base.y == pytest.approx(0.5, abs=2e-3)
    assert odom.distance_m == pytest.approx(0.1 * (math.pi / 2) / 0.2, rel=1e-6)


def test_inverse_kinematics_uses_half_track() -> None:
    wl, wr = twist_to_wheel_rates(Twist(0.1, 1.0), RobotConfig())
    assert wr == pytest.approx((0.1 + 1.0 * L / 2) / R)
    assert wl == pytest.approx((0.1 - 1.0 * L / 2) / R)


@pytest.mark.parametrize("v,w", [(0.1, 0.0), (0.0, 1.5), (0.2, -0.7), (-0.05, 0.3)])
def test_cmd_vel_wheels_odometry_round_trip(v: float, w: float) -> None:
    cfg = RobotConfig()
    wl, wr = twist_to_wheel_rates(Twist(v, w), cfg)
    back = wheel_rates_to_twist(wl, wr, cfg)
    assert back.linear_x == pytest.approx(v)
    assert back.angular_z == pytest.approx(w)
    msg = drive(DiffDriveOdometry(cfg), wl, wr, 2.0)
    assert msg.linear_x == pytest.approx(v)
    assert msg.angular_z == pytest.approx(w)


def test_seed_mode_reproduces_the_original_bug() -> None:
    """The original drove ω·0.178 per wheel: the true yaw rate is 2·0.178/0.160 = 2.225× the command."""
    seed = RobotConfig(odometry_mode="seed")
    wl, wr = twist_to_wheel_rates(Twist(0.0, 1.0), seed)
    true_rate = (wr - wl) * R / L  # what the real wheels do
    assert true_rate == pytest.approx(2 * 0.178 / 0.160)
    # and its odometry (l = 0.178) under-reports that yaw by 0.160/0.178
    reported = wheel_rates_to_twist(wl, wr, seed).angular_z
    assert reported / true_rate == pytest.approx(0.160 / 0.178)


def test_limits_and_bad_input() -> None:
    cfg = RobotConfig()
    t = clamp_twist(Twist(5.0, -50.0), cfg)
    assert (t.linear_x, t.angular_z) == (0.22, -2.84)
    assert clamp_twist(Twist(float("nan"), float("inf")), cfg) == Twist(0.0, 0.0)
    odom = DiffDriveOdometry(cfg)
    odom.update(WheelEncoders(0.0, 0.0, 0.0))
    odom.update(WheelEncoders(0.1, float("nan"), 1.0))
    odom.update(WheelEncoders(0.2, 0.5, 0.5))
    odom.update(WheelEncoders(0.15, 1.0, 1.0))  # time going backwards
    assert odom.skipped == 2
    assert np.isfinite(odom.T_odom_base.as_array()).all()
