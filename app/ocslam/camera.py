"""The robot's pinhole camera and the LIDAR plane it looks at (paper §2.5.2, improved geometry).

:class:`CameraModel` holds the camera model ``P = K [R | t]`` with the camera's pose on the robot
(``T_base_optical``, from the URDF) and the LIDAR's (``T_base_scan``). Every image column ``u`` is a
plane through the camera centre; it cuts the LIDAR plane in a half-line from the *apex* (where the
camera's vertical axis meets the LIDAR plane): :meth:`CameraModel.column_bearings_scan`. The
bounding areas built on these half-lines are in :mod:`app.ocslam.projection`.

Frames: ``base`` is ``base_footprint`` (z = 0 on the floor, x forward, y left, z up); the optical
frame is z forward, x right, y down; ``base_scan`` is the LIDAR frame (assumed level).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from app.ocslam.messages import CameraInfo
from app.ocslam.se2 import Pose2

FloatArray = NDArray[np.float64]

#: Rotation from a REP-103 camera link (x forward, y left, z up) to its optical frame (z fwd, x right, y down).
R_LINK_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def _rpy_matrix(roll: float, pitch: float, yaw: float) -> FloatArray:
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1.0]])
    ry = np.array([[cp, 0, sp], [0, 1.0, 0], [-sp, 0, cp]])
    rx = np.array([[1.0, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


def transform_matrix(xyz: Sequence[float], rpy: Sequence[float] = (0.0, 0.0, 0.0)) -> FloatArray:
    """(4, 4) homogeneous transform from a URDF-style ``xyz`` / ``rpy`` (fixed axes X, Y, Z)."""
    T = np.eye(4)
    T[:3, :3] = _rpy_matrix(*rpy)
    T[:3, 3] = np.asarray(xyz, dtype=np.float64)
    return T


@dataclass(frozen=True, eq=False)
class CameraModel:
    """Pinhole camera on the robot, plus the LIDAR's pose.

    ``T_base_optical``: (4, 4) pose of the optical frame in ``base_footprint``.
    ``T_base_scan``: (4, 4) pose of the LIDAR frame in ``base_footprint`` (level; its height is the
    LIDAR plane).
    """

    info: CameraInfo
    T_base_optical: FloatArray
    T_base_scan: FloatArray

    def __post_init__(self) -> None:
        for name in ("T_base_optical", "T_base_scan"):
            m = np.asarray(getattr(self, name), dtype=np.float64)
            if m.shape != (4, 4) or not np.all(np.isfinite(m)):
                raise ValueError(f"CameraModel.{name} must be a finite (4, 4) matrix")
            object.__setattr__(self, name, m)
        K = np.asarray(self.info.K, dtype=np.float64)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
            raise ValueError("CameraModel: K must be a finite (3, 3) matrix with positive focal lengths")

    @staticmethod
    def from_mount(
        info: CameraInfo,
        camera_xyz: Sequence[float] = (0.0, 0.0, 0.19),
        camera_rpy: Sequence[float] = (0.0, 0.0, 0.0),
        scan_xyz: Sequence[float] = (-0.032, 0.0, 0.173),
        scan_yaw: float = 0.0,
    ) -> CameraModel:
        """Build from the camera *link* pose (REP-103 axes) and the LIDAR position in ``base_footprint``."""
        T_base_link = transform_matrix(camera_xyz, camera_rpy)
        T_link_optical = np.eye(4)
        T_link_optical[:3, :3] = R_LINK_OPTICAL
        return CameraModel(info, T_base_link @ T_link_optical, transform_matrix(scan_xyz, (0.0, 0.0, scan_yaw)))

    # -- basic quantities ---------------------------------------------------------------------------
    @property
    def K(self) -> FloatArray:
        return np.asarray(self.info.K, dtype=np.float64)

    @cached_property
    def K_inv(self) -> FloatArray:
        return np.asarray(np.linalg.inv(self.K), dtype=np.float64)

    @property
    def R_base_optical(self) -> FloatArray:
        return self.T_base_optical[:3, :3]

    @cached_property
    def _R_rays(self) -> tuple[FloatArray, FloatArray]:
        """``(K⁻¹ᵀ, Rᵀ)``: the matrices :meth:`pixel_rays` applies, in its order (one lookup a call)."""
        return self.K_inv.T, self.R_base_optical.T

    @cached_property
    def _scan_rotation(self) -> tuple[float, float]:
        """``(cos, sin)`` of the rotation from ``base_footprint`` to ``base_scan`` (``−yaw`` of the LIDAR)."""
        yaw = -self.T_base_scan_2d.yaw
        return math.cos(yaw), math.sin(yaw)

    @property
    def center_base(self) -> FloatArray:
        """(3,) camera centre in ``base_footprint``."""
        return self.T_base_optical[:3, 3]

    @property
    def lidar_height(self) -> float:
        """Height of the LIDAR plane above the floor (m)."""
        return float(self.T_base_scan[2, 3])

    @property
    def camera_height(self) -> float:
        return float(self.T_base_optical[2, 3])

    @cached_property
    def T_base_scan_2d(self) -> Pose2:
        """The LIDAR frame's planar pose in ``base_footprint``."""
        R = self.T_base_scan[:3, :3]
        return Pose2(float(self.T_base_scan[0, 3]), float(self.T_base_scan[1, 3]), float(np.arctan2(R[1, 0], R[0, 0])))

    @cached_property
    def P(self) -> FloatArray:
        """(3, 4) projection matrix ``K [R | t]`` mapping homogeneous ``base_footprint`` points to pixels."""
        T_optical_base = np.linalg.inv(self.T_base_optical)
        return self.K @ T_optical_base[:3, :]

    def project(self, points_base: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``(N, 3)`` base points → ``(N, 2)`` pixels ``(u, v)`` and ``(N,)`` optical depths (≤ 0: behind)."""
        p = np.asarray(points_base, dtype=np.float64).reshape(-1, 3)
        hp = np.empty((len(p), 4))
        hp[:, :3] = p
        hp[:, 3] = 1.0
        h = hp @ self.P.T
        z = h[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = h[:, :2] / z[:, None]
        return uv, z

    def pixel_rays(self, uv: FloatArray) -> FloatArray:
        """``(N, 2)`` pixels → ``(N, 3)`` unit ray directions in ``base_footprint``."""
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        h = np.empty((len(uv), 3))
        h[:, :2] = uv
        h[:, 2] = 1.0
        K_inv_T, R_T = self._R_rays
        d = h @ K_inv_T @ R_T
        sq = d * d  # the norm as np.linalg.norm sums it: ((x² + y²) + z²)
        return d / np.sqrt(sq[:, 0] + sq[:, 1] + sq[:, 2])[:, None]

    def rays_to_plane(self, uv: FloatArray, z: float) -> tuple[FloatArray, NDArray[np.bool_]]:
        """Intersect the rays of ``(N, 2)`` pixels with the horizontal plane at height ``z`` (base frame).

        Returns ``(N, 3)`` points and an ``(N,)`` mask of rays that hit the plane in front of the camera.
        """
        d = self.pixel_rays(uv)
        c = self.center_base
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (z - c[2]) / d[:, 2]
        ok = np.isfinite(s) & (s > 0.0)
        s = np.where(ok, s, np.nan)
        return c[None, :] + s[:, None] * d, ok

    # -- the LIDAR plane ---------------------------------------------------------------------------
    @cached_property
    def apex_base(self) -> FloatArray:
        """(2,) where every image column's half-line starts on the LIDAR plane (base frame, x/y)."""
        c = self.center_base
        y_opt = self.R_base_optical[:, 1]
        if abs(y_opt[2]) < 1e-6:
            return c[:2].copy()
        s = (self.lidar_height - c[2]) / y_opt[2]
        return (c + s * y_opt)[:2]

    @cached_property
    def apex_scan(self) -> FloatArray:
        """(2,) the apex in ``base_scan``."""
        return self.T_base_scan_2d.inverse().transform_points(self.apex_base[None, :])[0]

    def column_directions_base(self, u: FloatArray) -> FloatArray:
        """``(N,)`` image columns → ``(N, 2)`` unit directions of their half-lines on the LIDAR plane (base)."""
        u = np.asarray(u, dtype=np.float64).reshape(-1)
        uv = np.empty((len(u), 2))
        uv[:, 0] = u
        uv[:, 1] = self.info.cy
        d = self.pixel_rays(uv)
        y0, y1, y2 = self.R_base_optical[:, 1].tolist()
        # n = y × d, then the line direction n × e_z = (n_y, −n_x)
        line = np.empty((len(u), 2))
        line[:, 0] = y2 * d[:, 0] - y0 * d[:, 2]
        line[:, 1] = -(y1 * d[:, 2] - y2 * d[:, 1])
        sq = line * line
        norm = np.sqrt(sq[:, 0] + sq[:, 1])[:, None]
        if np.all(norm > 1e-9):
            line /= np.maximum(norm, 1e-12)
        else:  # a column in the plane of the camera's vertical axis and its ray: the ray's own direction
            dn = d[:, :2] * d[:, :2]
            fallback = d[:, :2] / np.maximum(np.sqrt(dn[:, 0] + dn[:, 1])[:, None], 1e-12)
            line = np.where(norm > 1e-9, line / np.maximum(norm, 1e-12), fallback)
        sign = np.sign(line[:, 0] * d[:, 0] + line[:, 1] * d[:, 1])
        sign[sign == 0] = 1.0
        line *= sign[:, None]
        return line

    def _columns_scan_xy(self, u: FloatArray) -> tuple[FloatArray, FloatArray]:
        """:meth:`column_directions_scan` as its two ``(N,)`` coordinate columns."""
        d = self.column_directions_base(u)
        c, s = self._scan_rotation
        dx, dy = d[:, 0], d[:, 1]
        return c * dx - s * dy, s * dx + c * dy

    def column_directions_scan(self, u: FloatArray) -> FloatArray:
        """``(N,)`` columns → ``(N, 2)`` unit half-line directions in ``base_scan``."""
        x, y = self._columns_scan_xy(u)
        out = np.empty((len(x), 2))
        out[:, 0] = x
        out[:, 1] = y
        return out

    def column_bearings_scan(self, u: FloatArray) -> FloatArray:
        """``(N,)`` columns → ``(N,)`` bearings (rad) of their half-lines about the apex, in ``base_scan``."""
        x, y = self._columns_scan_xy(u)
        return np.arctan2(y, x)

    def ground_ranges(self, uv: FloatArray) -> FloatArray:
        """``(N, 2)`` pixels → ``(N,)`` horizontal distance from the apex to where the ray meets the floor.

        ``inf`` for rays at or above the horizon.
        """
        p, ok = self.rays_to_plane(uv, 0.0)
        ax, ay = self.apex_base.tolist()
        x, y = p[:, 0] - ax, p[:, 1] - ay
        r = np.sqrt(x * x + y * y)  # the norm as np.linalg.norm sums it (x² + y²)
        r[~ok] = np.inf
        return r

    def bearing_ranges_scan(self, points_scan: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``(N, 2)`` points in ``base_scan`` → ``(N,)`` bearings and ``(N,)`` ranges about the apex."""
        p = np.asarray(points_scan, dtype=np.float64).reshape(-1, 2)
        ax, ay = self.apex_scan.tolist()
        dx, dy = p[:, 0] - ax, p[:, 1] - ay
        return np.arctan2(dy, dx), np.hypot(dx, dy)


def ground_plane_point(u: float, v: float, camera: CameraModel) -> tuple[float, float] | None:
    """Where the ray through pixel ``(u, v)`` meets the floor ``z = 0``: ``(x, y)`` in ``base_footprint``.

    ``None`` if the ray points at or above the horizon.
    """
    p, ok = camera.rays_to_plane(np.array([[u, v]], dtype=np.float64), 0.0)
    if not ok[0]:
        return None
    return float(p[0, 0]), float(p[0, 1])
