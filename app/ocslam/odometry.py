"""Differential-drive kinematics and wheel odometry (paper §2.2), with the original's bugs fixed.

Forward (paper, from encoder deltas Δp over Δt)::

    v = (Δp_r + Δp_l)·r / (2Δt)          ω = (Δp_r − Δp_l)·r / (l·Δt)
    θ_i = θ_{i−1} + ω·Δt                 x_i = x_{i−1} + v·cos(θ_i)·Δt,  y_i likewise with sin

Inverse (correct): ``ω_r = (v + ω·l/2)/r``, ``ω_l = (v − ω·l/2)/r`` with ``l = 0.160``. The paper and
its code use ``ω·l`` and ``l = 0.178`` (spec §3); ``RobotConfig.odometry_mode = "seed"`` reproduces that.

Example:
    >>> odom = DiffDriveOdometry(RobotConfig())
    >>> odom.update(WheelEncoders(0.0, 0.0, 0.0))
    >>> msg = odom.update(WheelEncoders(1.0, 1.0 / 0.033, 1.0 / 0.033))   # both wheels roll 1 m
    >>> round(msg.T_odom_base.x, 6)
    1.0
"""

from __future__ import annotations

import math

from app.ocslam.config import RobotConfig
from app.ocslam.messages import Odometry, Twist, WheelEncoders
from app.ocslam.se2 import Pose2, wrap_angle

#: The original implementation's TRACK_WIDTH (the Burger's body width, not its wheel separation).
SEED_TRACK_WIDTH_M = 0.178


def _track(robot: RobotConfig) -> float:
    return SEED_TRACK_WIDTH_M if robot.odometry_mode == "seed" else robot.wheel_separation_m


def clamp_twist(twist: Twist, robot: RobotConfig) -> Twist:
    """Clamp to the robot's limits (0.22 m/s, 2.84 rad/s for the Burger)."""
    v, w = float(twist.linear_x), float(twist.angular_z)
    v = max(-robot.max_linear_mps, min(robot.max_linear_mps, v)) if math.isfinite(v) else 0.0
    w = max(-robot.max_angular_rps, min(robot.max_angular_rps, w)) if math.isfinite(w) else 0.0
    return Twist(v, w)


def twist_to_wheel_rates(twist: Twist, robot: RobotConfig) -> tuple[float, float]:
    """cmd_vel → ``(ω_left, ω_right)`` wheel rates in rad/s.

    Correct mode: ``(v ∓ ω·l/2)/r``. Seed mode: ``(v ∓ ω·0.178)/r`` (the original's bug: the robot
    then turns 2·0.178/0.160 ≈ 2.2× faster than commanded).
    """
    t = clamp_twist(twist, robot)
    r = robot.wheel_radius_m
    if robot.odometry_mode == "seed":
        half = t.angular_z * SEED_TRACK_WIDTH_M
    else:
        half = t.angular_z * robot.wheel_separation_m / 2.0
    return (t.linear_x - half) / r, (t.linear_x + half) / r


def wheel_rates_to_twist(omega_left: float, omega_right: float, robot: RobotConfig) -> Twist:
    """Wheel rates (rad/s) → body twist, with the odometry's track width."""
    r = robot.wheel_radius_m
    return Twist((omega_right + omega_left) * r / 2.0, (omega_right - omega_left) * r / _track(robot))


class DiffDriveOdometry:
    """Integrates absolute wheel angles into the ``odom → base_footprint`` transform.

    The odometry starts at the identity (``odom`` = the robot's start pose), as on the real robot.
    """

    def __init__(self, robot: RobotConfig, T_odom_base: Pose2 | None = None) -> None:
        self.robot = robot
        self.T_odom_base = T_odom_base or Pose2()
        self._last: WheelEncoders | None = None
        self.linear_x = 0.0
        self.angular_z = 0.0
        self.distance_m = 0.0
        self.skipped = 0  # readings rejected (non-finite, time going backwards)

    def reset(self, T_odom_base: Pose2 | None = None) -> None:
        self.T_odom_base = T_odom_base or Pose2()
        self._last = None
        self.linear_x = self.angular_z = self.distance_m = 0.0

    def update(self, enc: WheelEncoders) -> Odometry:
        """Consume one encoder reading; returns the new ``Odometry`` (first reading initialises)."""
        if not (math.isfinite(enc.left_rad) and math.isfinite(enc.right_rad) and math.isfinite(enc.stamp)):
            self.skipped += 1
            return self.odometry(enc.stamp if math.isfinite(enc.stamp) else 0.0)
        last, self._last = self._last, enc
        if last is None:
            return self.odometry(enc.stamp)
        dt = enc.stamp - last.stamp
        if dt < 0:
            self.skipped += 1
            return self.odometry(enc.stamp)
        r = self.robot.wheel_radius_m
        d_left = (enc.left_rad - last.left_rad) * r
        d_right = (enc.right_rad - last.right_rad) * r
        ds = (d_right + d_left) / 2.0
        dtheta = (d_right - d_left) / _track(self.robot)
        # The paper's Euler step: heading first, then the position along the *new* heading.
        p = self.T_odom_base
        yaw = float(wrap_angle(p.yaw + dtheta))
        self.T_odom_base = Pose2(p.x + ds * math.cos(yaw), p.y + ds * math.sin(yaw), yaw)
        self.distance_m += abs(ds)
        if dt > 0:
            self.linear_x, self.angular_z = ds / dt, dtheta / dt
        return self.odometry(enc.stamp)

    def odometry(self, stamp: float) -> Odometry:
        return Odometry(stamp=stamp, T_odom_base=self.T_odom_base, linear_x=self.linear_x, angular_z=self.angular_z)
