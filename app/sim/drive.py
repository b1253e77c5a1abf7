"""The kinematic differential drive and the robot's collision probe.

Motion is kinematic, not dynamic: each fixed step the commanded wheel rates (``cmd_vel`` through
:func:`~app.ocslam.odometry.twist_to_wheel_rates`) pass a first-order motor lag
(``sim.motor_time_constant_s``); the wheels turn by ``ω·dt`` (what the encoders measure) while the ground
sees ``r·ω·(1 − slip)`` with a slowly varying per-wheel slip (an Ornstein–Uhlenbeck process:
``encoders.slip_std``, ``encoders.slip_tau_s``) and an optional per-run wheel-radius error
(``encoders.radius_error_std``). The pose integrates exactly along the arc. A step that would put the
robot's collision cylinder into anything is refused (the robot stalls, its wheels slip), so it never
passes through walls or objects. Deterministic for a seed; no contact dynamics to tune or to explode.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.ocslam.se2 import Pose2

__all__ = ["CollisionProbe", "KinematicDrive"]


class CollisionProbe:
    """The robot's collision cylinder (radius ``radius``, ``sim.robot_height_m`` tall from 12 mm above the
    floor, centre at ``z``): a pybullet body parked out of view, moved to a pose only to ask whether it
    touches one of ``world_bodies``."""

    def __init__(self, p: Any, client: int, body: int, *, z: float, radius: float, sim_config: Any,
                 world_bodies: set[int]) -> None:
        self._p = p
        self.client = client
        self.body = body
        self.z = z
        self.radius = radius
        self.sim_config = sim_config  # read at each query: sim.robot_height_m
        self.world_bodies = world_bodies

    def free(self, x: float, y: float) -> bool:
        """True if the robot's collision cylinder at ``(x, y)`` touches nothing."""
        p, cid = self._p, self.client
        r = self.radius
        z = self.z
        hh = self.sim_config.robot_height_m / 2
        cands = p.getOverlappingObjects([x - r, y - r, z - hh], [x + r, y + r, z + hh], physicsClientId=cid)
        if not cands:
            return True
        moved = False
        for uid, _ in cands:
            if uid not in self.world_bodies:
                continue
            if not moved:
                p.resetBasePositionAndOrientation(self.body, [x, y, z], [0, 0, 0, 1], physicsClientId=cid)
                moved = True
            if p.getClosestPoints(self.body, uid, 0.0, physicsClientId=cid):
                return False
        return True


class KinematicDrive:
    """The drive's state: true pose ``(x, y, yaw)`` of ``base_footprint`` in the world, true wheel angles
    and rates (left, right), slip, and what happened on the way (stall, collisions, distance).

    ``rng`` is the motion noise stream (the wheel-radius error is drawn from it here, then the slip at
    every step); ``encoders``: the ``encoders`` config section.
    """

    def __init__(self, start: Pose2, rng: np.random.Generator, encoders: Any) -> None:
        self.rng = rng
        self.pose: NDArray[np.float64] = np.array([start.x, start.y, start.yaw], dtype=np.float64)
        self.phi = np.zeros(2)  # true wheel angles (left, right)
        self.omega = np.zeros(2)  # actual wheel rates
        self.omega_cmd = np.zeros(2)
        self.slip = np.zeros(2)
        e = encoders
        self.radius_scale = 1.0 + rng.normal(0.0, e.radius_error_std, 2) if e.radius_error_std > 0 else np.ones(2)
        self.blocked = False
        self.collisions = 0
        self.distance_m = 0.0

    def step(self, n: int, dt: float, *, wheel_radius_m: float, wheel_separation_m: float, motor_time_constant_s: float,
             encoders: Any, pose_free: Callable[[float, float], bool]) -> bool:
        """Advance ``n`` fixed steps of ``dt``; ``pose_free(x, y)`` says whether the robot fits there.
        True if the robot moved or turned in any of them."""
        e = encoders
        tau = motor_time_constant_s
        k_motor = 1.0 - math.exp(-dt / tau) if tau > 0 else 1.0
        a_slip = math.exp(-dt / max(e.slip_tau_s, 1e-9))
        b_slip = e.slip_std * math.sqrt(max(1.0 - a_slip * a_slip, 0.0))
        r = wheel_radius_m
        sep = wheel_separation_m
        rng = self.rng
        moved = False
        for _ in range(int(n)):
            self.omega += (self.omega_cmd - self.omega) * k_motor
            if b_slip > 0:
                self.slip = self.slip * a_slip + b_slip * rng.standard_normal(2)
            self.phi += self.omega * dt
            ground = r * self.radius_scale * self.omega * (1.0 - self.slip)
            v = 0.5 * (ground[0] + ground[1])
            w = (ground[1] - ground[0]) / sep
            x, y, th = self.pose
            if abs(v) > 1e-12 or abs(w) > 1e-12:
                if abs(w) < 1e-9:
                    nx, ny = x + v * dt * math.cos(th), y + v * dt * math.sin(th)
                else:
                    R = v / w
                    nx = x + R * (math.sin(th + w * dt) - math.sin(th))
                    ny = y - R * (math.cos(th + w * dt) - math.cos(th))
                nth = th + w * dt
                if (nx != x or ny != y) and not pose_free(nx, ny):
                    # stall: the cylinder may still turn in place; the wheels slip
                    if not self.blocked:
                        self.collisions += 1
                    self.blocked = True
                    self.pose = np.array([x, y, nth])
                else:
                    self.blocked = False
                    self.distance_m += math.hypot(nx - x, ny - y)
                    self.pose = np.array([nx, ny, nth])
                moved = True
        return moved
