"""SE(2) rigid transforms, scalar and vectorised.

Convention (REP-103, and the names used throughout the code): ``T_a_b`` is the pose of frame ``b``
expressed in frame ``a``. It maps points given in ``b`` to ``a``: ``p_a = T_a_b ∘ p_b``. Composition
chains frames: ``T_a_c = T_a_b ∘ T_b_c``.

Vectorised functions take ``(..., 3)`` arrays of ``(x, y, yaw)`` and broadcast like numpy.

Example:
    >>> T_map_odom = Pose2(1.0, 0.0, 0.0)
    >>> T_odom_base = Pose2(0.0, 2.0, np.pi / 2)
    >>> T_map_base = T_map_odom @ T_odom_base
    >>> T_map_base.transform_points(np.array([[1.0, 0.0]]))  # (N, 2) points in base -> map
    array([[1., 3.]])
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


def wrap_angle(a: ArrayLike) -> FloatArray | float:
    """Wrap angle(s) in radians to [-pi, pi)."""
    if isinstance(a, (float, int)):  # a scalar: Python's float ``%`` is numpy's (same result, less overhead)
        return (float(a) + math.pi) % (2.0 * math.pi) - math.pi
    w = (np.asarray(a, dtype=np.float64) + np.pi) % (2.0 * np.pi) - np.pi
    return float(w) if np.ndim(w) == 0 else w


@dataclass(frozen=True, slots=True)
class Pose2:
    """A 2D rigid transform / pose ``(x, y, yaw)`` in metres and radians."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0

    # -- constructors -------------------------------------------------------------------------
    @staticmethod
    def identity() -> Pose2:
        return Pose2(0.0, 0.0, 0.0)

    @staticmethod
    def from_array(a: ArrayLike) -> Pose2:
        x, y, t = np.asarray(a, dtype=np.float64).reshape(3)
        return Pose2(float(x), float(y), float(t))

    @staticmethod
    def from_matrix(m: ArrayLike) -> Pose2:
        m = np.asarray(m, dtype=np.float64)
        return Pose2(float(m[0, 2]), float(m[1, 2]), float(np.arctan2(m[1, 0], m[0, 0])))

    # -- conversions ---------------------------------------------------------------------------
    def as_array(self) -> FloatArray:
        return np.array([self.x, self.y, self.yaw], dtype=np.float64)

    def as_matrix(self) -> FloatArray:
        """(3, 3) homogeneous matrix."""
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        return np.array([[c, -s, self.x], [s, c, self.y], [0.0, 0.0, 1.0]])

    def as_quaternion_wxyz(self) -> tuple[float, float, float, float]:
        """Rotation about +z as a (w, x, y, z) quaternion (viser's convention)."""
        return (float(np.cos(self.yaw / 2)), 0.0, 0.0, float(np.sin(self.yaw / 2)))

    # -- group operations ----------------------------------------------------------------------
    # scalar math on Python floats (math.cos/sin give numpy's values here, at a fraction of the overhead)
    def __matmul__(self, other: Pose2) -> Pose2:
        yaw = float(self.yaw)
        c, s = math.cos(yaw), math.sin(yaw)
        ox, oy = float(other.x), float(other.y)
        return Pose2(
            float(self.x) + c * ox - s * oy,
            float(self.y) + s * ox + c * oy,
            float(wrap_angle(yaw + float(other.yaw))),
        )

    def inverse(self) -> Pose2:
        yaw, x, y = float(self.yaw), float(self.x), float(self.y)
        c, s = math.cos(yaw), math.sin(yaw)
        return Pose2(-c * x - s * y, s * x - c * y, float(wrap_angle(-yaw)))

    def between(self, other: Pose2) -> Pose2:
        """The relative motion ``self⁻¹ ∘ other`` (``other`` expressed in ``self``)."""
        return self.inverse() @ other

    def transform_points(self, points: ArrayLike) -> FloatArray:
        """Map ``(N, 2)`` points from this pose's child frame to its parent frame."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        yaw = float(self.yaw)
        c, s = math.cos(yaw), math.sin(yaw)
        tx, ty = float(self.x), float(self.y)
        if len(p) == 1:  # one point (the most frequent call): Python floats, the same IEEE operations
            x, y = p[0].tolist()
            return np.array([[c * x - s * y + tx, s * x + c * y + ty]])
        # both columns at once, elementwise as ``c·x − s·y + tx``, ``s·x + c·y + ty`` (the same roundings)
        out = p[:, :1] * np.array([c, s])
        out += p[:, 1:] * np.array([-s, c])
        out += np.array([tx, ty])
        return out

    def distance(self, other: Pose2) -> float:
        return float(np.hypot(self.x - other.x, self.y - other.y))

    def __iter__(self):
        yield self.x
        yield self.y
        yield self.yaw


# -- vectorised (N, 3) helpers ------------------------------------------------------------------


def compose(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """``a ∘ b`` for ``(..., 3)`` pose arrays (broadcasting)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    y = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    t = wrap_angle(a[..., 2] + b[..., 2])
    return np.stack([x, y, np.asarray(t)], axis=-1)


def inverse(a: ArrayLike) -> FloatArray:
    """Inverse of ``(..., 3)`` poses."""
    a = np.asarray(a, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = -c * a[..., 0] - s * a[..., 1]
    y = s * a[..., 0] - c * a[..., 1]
    return np.stack([x, y, np.asarray(wrap_angle(-a[..., 2]))], axis=-1)


def between(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """Relative motion ``a⁻¹ ∘ b`` for ``(..., 3)`` pose arrays."""
    return compose(inverse(a), b)


def transform_points(pose: ArrayLike, points: ArrayLike) -> FloatArray:
    """Apply one ``(3,)`` pose to ``(N, 2)`` points."""
    return Pose2.from_array(pose).transform_points(points)


def interpolate(t: ArrayLike, stamps: ArrayLike, poses: ArrayLike) -> FloatArray:
    """Interpolate ``(N, 3)`` poses stamped ``(N,)`` (increasing) at times ``t`` (clamped at the ends).

    Translation is linear; yaw follows the shortest arc.
    """
    stamps = np.asarray(stamps, dtype=np.float64)
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    t = np.asarray(t, dtype=np.float64)
    if len(stamps) == 0:
        raise ValueError("interpolate: no poses")
    if len(stamps) == 1:
        return np.broadcast_to(poses[0], t.shape + (3,)).copy()
    i = np.clip(np.searchsorted(stamps, t, side="right") - 1, 0, len(stamps) - 2)
    t0, t1 = stamps[i], stamps[i + 1]
    dt = np.where(t1 > t0, t1 - t0, 1.0)
    a = np.clip((t - t0) / dt, 0.0, 1.0)
    p0, p1 = poses[i], poses[i + 1]
    xy = p0[..., :2] + a[..., None] * (p1[..., :2] - p0[..., :2])
    yaw = wrap_angle(p0[..., 2] + a * wrap_angle(p1[..., 2] - p0[..., 2]))
    return np.concatenate([xy, np.asarray(yaw)[..., None]], axis=-1)
