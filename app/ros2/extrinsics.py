"""Sensor extrinsics from bags or config, and the planar scan the core expects.

The core's SLAM takes the LIDAR's pose in ``base_footprint`` as a planar ``Pose2``. A real LIDAR may be
mounted tilted or upside down: its ``(4, 4)`` pose ``T_base_scan`` then has a rotation that is not a
yaw. :func:`level_scan` moves the returns into a *level* frame at the sensor's position (z up, x along
the sensor's x axis projected onto the floor) and re-bins them into the same beam layout; an upside-down
LIDAR (a 180° roll or pitch) thereby has its scan mirrored in the plane, exactly.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from app.ocslam.messages import LaserScan
from app.ocslam.se2 import Pose2
from app.ocslam.sync import bin_to_beams

FloatArray = NDArray[np.float64]


def matrix_from_xyzrpy(v: Sequence[float]) -> FloatArray:
    """``[x, y, z, roll, pitch, yaw]`` (m, rad; fixed-axis XYZ as in URDF / tf2) → ``(4, 4)``."""
    v = [float(a) for a in v]
    if len(v) != 6 or not all(math.isfinite(a) for a in v):
        raise ValueError(f"extrinsic must be 6 finite numbers x, y, z, roll, pitch, yaw (got {v})")
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", v[3:]).as_matrix()
    T[:3, 3] = v[:3]
    return T


def is_level(T_base_scan: FloatArray, tol: float = 1e-6) -> bool:
    """True when the sensor's z axis is the base's z axis (a pure yaw + translation)."""
    return bool(abs(np.asarray(T_base_scan)[2, 2] - 1.0) < tol)


def planar_mount(T_base_scan: FloatArray) -> Pose2:
    """The level frame's planar pose in ``base_footprint``: the sensor's position and the heading of its
    x axis projected onto the floor (if the x axis is vertical, of its y axis turned by −90°)."""
    T = np.asarray(T_base_scan, dtype=np.float64)
    x_axis = T[:3, 0]
    if math.hypot(x_axis[0], x_axis[1]) > 1e-6:
        yaw = math.atan2(x_axis[1], x_axis[0])
    else:
        yaw = math.atan2(T[1, 1], T[0, 1]) - math.pi / 2
    return Pose2(float(T[0, 3]), float(T[1, 3]), yaw)


def level_scan(scan: LaserScan, T_base_scan: FloatArray) -> tuple[LaserScan, Pose2]:
    """``scan`` taken by a sensor at ``T_base_scan`` (4, 4) → ``(scan in the level frame, T_base_level)``.

    Each return ``(r cos a, r sin a, 0)`` is rotated into the base frame, projected onto the floor and
    expressed in the level frame; returns re-binned into the same ``angle_min``/``angle_increment``
    beams (the nearest return per beam). Level mounts pass through unchanged (only the pose is read).
    """
    T = np.asarray(T_base_scan, dtype=np.float64)
    T_base_level = planar_mount(T)
    if is_level(T):
        return scan, T_base_level
    m = scan.valid_mask()
    r = np.asarray(scan.ranges, dtype=np.float64)[m]
    a = scan.angles[m]
    local = np.stack([r * np.cos(a), r * np.sin(a), np.zeros_like(r)], axis=1)
    base = local @ T[:3, :3].T  # directions in the base frame (translation handled by the level frame)
    c, s = math.cos(T_base_level.yaw), math.sin(T_base_level.yaw)
    level = np.stack([c * base[:, 0] + s * base[:, 1], -s * base[:, 0] + c * base[:, 1]], axis=1)
    # beams that had no return keep "no return" (inf) so free space is still cleared along them
    out = bin_to_beams(scan, level)
    return replace(scan, ranges=out, frame_id=scan.frame_id + "_level"), T_base_level
