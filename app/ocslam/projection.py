"""Detection boxes projected onto the LIDAR plane ("bounding areas", paper §2.5.2).

Improved geometry (default): the camera model ``P = K [R | t]`` with the camera's pose on the robot
(``T_base_optical``, from the URDF) and the LIDAR's (``T_base_scan``). Every image column ``u`` is a
plane through the camera centre; it cuts the LIDAR plane in a half-line from the *apex* (where the
camera's vertical axis meets the LIDAR plane). A box ``(x1, y1, x2, y2)`` becomes the wedge between
the half-lines of its left and right edges, starting at the *near range* where the ray through its
bottom edge meets the floor (``z = 0``), and ending at ``max_range_m``. The *bisector* is the half-line
of the box's centre column. All areas are shapely polygons in the ``base_scan`` frame (2D, metres).

Seed-faithful geometry (:func:`seed_bounding_areas`): the original implementation's formulas
(spec §1.2–1.4): camera 4 cm above the LIDAR at its origin, calibrated K, the 672×505.05 image with
flipped rows, the right edge widened by 1.05, ranges clamped at 22.64 m, strict containment, and a
point may belong to several areas.

Frames: ``base`` is ``base_footprint`` (z = 0 on the floor, x forward, y left, z up); the optical
frame is z forward, x right, y down; ``base_scan`` is the LIDAR frame (assumed level).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Sequence

import numpy as np
import shapely
from numpy.typing import NDArray
from shapely.geometry import Polygon

from app.ocslam.messages import CameraInfo, Detection, Detections
from app.ocslam.se2 import Pose2

FloatArray = NDArray[np.float64]

#: Rotation from a REP-103 camera link (x forward, y left, z up) to its optical frame (z fwd, x right, y down).
R_LINK_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])

#: Points of a wedge's far arc.
_ARC_SEGMENTS = 12


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


# ----------------------------------------------------------------------------------------------
# Camera model
# ----------------------------------------------------------------------------------------------


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
    ) -> "CameraModel":
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
        h = np.hstack([p, np.ones((len(p), 1))]) @ self.P.T
        z = h[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = h[:, :2] / z[:, None]
        return uv, z

    def pixel_rays(self, uv: FloatArray) -> FloatArray:
        """``(N, 2)`` pixels → ``(N, 3)`` unit ray directions in ``base_footprint``."""
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        d = np.hstack([uv, np.ones((len(uv), 1))]) @ self.K_inv.T @ self.R_base_optical.T
        return d / np.linalg.norm(d, axis=1, keepdims=True)

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
        cy = self.info.cy
        d = self.pixel_rays(np.stack([u, np.full_like(u, cy)], axis=1))
        y = self.R_base_optical[:, 1]
        # n = y × d, then the line direction n × e_z = (n_y, −n_x)
        nx = y[1] * d[:, 2] - y[2] * d[:, 1]
        ny = y[2] * d[:, 0] - y[0] * d[:, 2]
        line = np.stack([ny, -nx], axis=1)
        norm = np.linalg.norm(line, axis=1, keepdims=True)
        fallback = d[:, :2] / np.maximum(np.linalg.norm(d[:, :2], axis=1, keepdims=True), 1e-12)
        line = np.where(norm > 1e-9, line / np.maximum(norm, 1e-12), fallback)
        sign = np.sign(np.sum(line * d[:, :2], axis=1))
        sign[sign == 0] = 1.0
        return line * sign[:, None]

    def column_directions_scan(self, u: FloatArray) -> FloatArray:
        """``(N,)`` columns → ``(N, 2)`` unit half-line directions in ``base_scan``."""
        d = self.column_directions_base(u)
        c, s = np.cos(-self.T_base_scan_2d.yaw), np.sin(-self.T_base_scan_2d.yaw)
        return np.stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1]], axis=1)

    def column_bearings_scan(self, u: FloatArray) -> FloatArray:
        """``(N,)`` columns → ``(N,)`` bearings (rad) of their half-lines about the apex, in ``base_scan``."""
        d = self.column_directions_scan(u)
        return np.arctan2(d[:, 1], d[:, 0])

    def ground_ranges(self, uv: FloatArray) -> FloatArray:
        """``(N, 2)`` pixels → ``(N,)`` horizontal distance from the apex to where the ray meets the floor.

        ``inf`` for rays at or above the horizon.
        """
        p, ok = self.rays_to_plane(uv, 0.0)
        r = np.linalg.norm(p[:, :2] - self.apex_base[None, :], axis=1)
        return np.where(ok, r, np.inf)

    def bearing_ranges_scan(self, points_scan: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``(N, 2)`` points in ``base_scan`` → ``(N,)`` bearings and ``(N,)`` ranges about the apex."""
        d = np.asarray(points_scan, dtype=np.float64).reshape(-1, 2) - self.apex_scan[None, :]
        return np.arctan2(d[:, 1], d[:, 0]), np.hypot(d[:, 0], d[:, 1])


def ground_plane_point(u: float, v: float, camera: CameraModel) -> tuple[float, float] | None:
    """Where the ray through pixel ``(u, v)`` meets the floor ``z = 0``: ``(x, y)`` in ``base_footprint``.

    ``None`` if the ray points at or above the horizon.
    """
    p, ok = camera.rays_to_plane(np.array([[u, v]], dtype=np.float64), 0.0)
    if not ok[0]:
        return None
    return float(p[0, 0]), float(p[0, 1])


# ----------------------------------------------------------------------------------------------
# Bounding areas (improved geometry)
# ----------------------------------------------------------------------------------------------


@dataclass(eq=False)
class BoundingArea:
    """One detection projected onto the LIDAR plane (all geometry in ``base_scan``).

    ``polygon``: the wedge; ``apex``: (2,) its tip; ``bearing_left``/``bearing_right``/``bearing_center``:
    bearings (rad) of the half-lines through the box's left edge, right edge and centre column;
    ``near_range_m``: distance from the apex to the floor point under the box's bottom edge
    (``inf`` if the bottom edge is at or above the horizon); ``near_range_lo``/``near_range_hi``: the same
    with the bottom edge moved down/up by the pixel margin; ``far_range_m``: the wedge's far arc;
    ``bisector``: (2, 2) segment ``[apex, apex + far·dir_center]``; ``truncated``: which box edges touch
    the image border (``left``, ``right``, ``top``, ``bottom``); ``box_px``: the box clipped to the image,
    in the camera's pixel grid; ``points``: the LIDAR points it received in the last update.
    """

    detection: Detection
    polygon: Polygon
    apex: FloatArray
    bearing_left: float
    bearing_right: float
    bearing_center: float
    near_range_m: float
    near_range_lo: float
    near_range_hi: float
    far_range_m: float
    bisector: FloatArray
    truncated: dict[str, bool] = field(default_factory=dict)
    box_px: FloatArray = field(default_factory=lambda: np.zeros(4))  # (x1, y1, x2, y2) clipped, camera pixels
    points: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))  # (K, 2) LIDAR points it received

    @property
    def label(self) -> str:
        return self.detection.label

    @property
    def confidence(self) -> float:
        return float(self.detection.confidence)

    @property
    def half_angle(self) -> float:
        return 0.5 * float(_angle_diff(self.bearing_left, self.bearing_right))

    @property
    def bottom_reliable(self) -> bool:
        """The bottom edge is inside the image and below the horizon: ``near_range_m`` is a real range."""
        return not self.truncated.get("bottom", False) and np.isfinite(self.near_range_m)

    @property
    def near_midpoint(self) -> FloatArray:
        """(2,) the midpoint of the near edge (on the bisector at the near range, or the apex)."""
        r = self.near_range_m if np.isfinite(self.near_range_m) else 0.0
        return self.apex + r * np.array([np.cos(self.bearing_center), np.sin(self.bearing_center)])

    def bisector_distance(self, points: FloatArray) -> FloatArray:
        """``(N, 2)`` points → ``(N,)`` perpendicular distances to the infinite bisector line."""
        a, b = self.bisector[0], self.bisector[1]
        d = b - a
        n = np.linalg.norm(d)
        if n < 1e-12:
            return np.linalg.norm(np.asarray(points) - a, axis=1)
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2) - a
        return np.abs(p[:, 0] * d[1] - p[:, 1] * d[0]) / n

    def angular_offsets(self, points_scan: FloatArray) -> FloatArray:
        """``(N, 2)`` points → ``(N,)`` signed bearing offsets (rad) from the bisector."""
        d = np.asarray(points_scan, dtype=np.float64).reshape(-1, 2) - self.apex[None, :]
        return _angle_diff(np.arctan2(d[:, 1], d[:, 0]), self.bearing_center)

    def contains_bearing(self, bearings: FloatArray, margin: float = 0.0) -> NDArray[np.bool_]:
        """``(N,)`` bearings about the apex → inside the wedge's angular span (widened by ``margin`` rad)."""
        off = _angle_diff(np.asarray(bearings, dtype=np.float64), self.bearing_center)
        return np.abs(off) <= self.half_angle + margin


def _angle_diff(a, b):
    return (np.asarray(a) - np.asarray(b) + np.pi) % (2.0 * np.pi) - np.pi


def _wedge_polygon(apex: FloatArray, b_left: float, b_right: float, r_near: float, r_far: float) -> Polygon:
    span = float(_angle_diff(b_left, b_right))
    t = b_right + np.linspace(0.0, span, _ARC_SEGMENTS + 1)
    far = apex[None, :] + r_far * np.stack([np.cos(t), np.sin(t)], axis=1)
    if r_near > 1e-6:
        near = apex[None, :] + r_near * np.stack([np.cos(t[::-1]), np.sin(t[::-1])], axis=1)
        ring = np.vstack([far, near])
    else:
        ring = np.vstack([far, apex[None, :]])
    poly = Polygon(ring)
    if not poly.is_valid:
        poly = shapely.make_valid(poly)
        if not isinstance(poly, Polygon):
            poly = Polygon(ring).buffer(0)
    return poly


def _box_scale(detections: Detections, width: float, height: float) -> tuple[float, float]:
    """``(sx, sy)`` from the detections' image size to ``width × height`` (1, 1 if the size is unknown)."""
    if detections.image_width > 0 and detections.image_height > 0:
        return width / detections.image_width, height / detections.image_height
    return 1.0, 1.0


def _scale_box(det: Detection, sx: float, sy: float) -> Detection:
    if sx == 1.0 and sy == 1.0:
        return det
    return Detection(det.x1 * sx, det.y1 * sy, det.x2 * sx, det.y2 * sy, det.class_id, det.confidence)


def area_from_box(
    det: Detection,
    camera: CameraModel,
    max_range_m: float,
    bottom_margin_px: float = 6.0,
    edge_margin_px: float = 8.0,
    near_tolerance: float = 0.25,
) -> BoundingArea | None:
    """The improved bounding area of one box in the camera's pixel grid (see module docstring).

    The polygon starts at ``near_range_lo·(1 − near_tolerance)``. Returns ``None`` for a degenerate
    box (non-finite, or empty after clipping to the image).
    """
    W, H = camera.info.width, camera.info.height
    vals = np.array([det.x1, det.y1, det.x2, det.y2], dtype=np.float64)
    if not np.all(np.isfinite(vals)):
        return None
    x1, x2 = np.clip(sorted((vals[0], vals[2])), 0.0, W)
    y1, y2 = np.clip(sorted((vals[1], vals[3])), 0.0, H)
    if x2 - x1 < 1.0 or y2 - y1 < 1.0:
        return None
    truncated = {
        "left": bool(x1 <= edge_margin_px),
        "right": bool(x2 >= W - edge_margin_px),
        "top": bool(y1 <= edge_margin_px),
        "bottom": bool(y2 >= H - edge_margin_px),
    }
    xc = 0.5 * (x1 + x2)
    bearings = camera.column_bearings_scan(np.array([x1, x2, xc]))
    b_left, b_right, b_center = (float(b) for b in bearings)
    rows = np.array([[xc, y2], [xc, min(y2 + bottom_margin_px, H)], [xc, max(y2 - bottom_margin_px, 0.0)]])
    near, near_lo, near_hi = (float(r) for r in camera.ground_ranges(rows))
    if truncated["bottom"] or not np.isfinite(near_lo):
        near_lo = 0.0  # the floor contact is not visible: no lower bound
    near_lo = min(near_lo, max_range_m)
    apex = camera.apex_scan
    r_poly = max(near_lo * (1.0 - near_tolerance), 0.0) if np.isfinite(near_lo) else 0.0
    r_poly = min(r_poly, 0.95 * max_range_m)
    poly = _wedge_polygon(apex, b_left, b_right, r_poly, max_range_m)
    direction = np.array([np.cos(b_center), np.sin(b_center)])
    bis = np.stack([apex, apex + max_range_m * direction])
    return BoundingArea(
        detection=det,
        polygon=poly,
        apex=apex.copy(),
        bearing_left=b_left,
        bearing_right=b_right,
        bearing_center=b_center,
        near_range_m=near,
        near_range_lo=near_lo,
        near_range_hi=near_hi,
        far_range_m=float(max_range_m),
        bisector=bis,
        truncated=truncated,
        box_px=np.array([x1, y1, x2, y2], dtype=np.float64),
    )


def bounding_areas(
    detections: Detections | Sequence[Detection],
    camera: CameraModel,
    max_range_m: float,
    bottom_margin_px: float = 6.0,
    edge_margin_px: float = 8.0,
    near_tolerance: float = 0.25,
) -> list[BoundingArea]:
    """Improved bounding areas of all boxes (``base_scan``); degenerate boxes are skipped.

    Boxes given for another image size than ``camera.info`` are rescaled to it.
    """
    boxes: Sequence[Detection]
    sx = sy = 1.0
    if isinstance(detections, Detections):
        boxes = detections.boxes
        sx, sy = _box_scale(detections, camera.info.width, camera.info.height)
    else:
        boxes = detections
    out = []
    for det in boxes:
        a = area_from_box(_scale_box(det, sx, sy), camera, max_range_m, bottom_margin_px, edge_margin_px, near_tolerance)
        if a is not None:
            a.detection = det
            out.append(a)
    return out


def camera_bound(camera: CameraModel, max_range_m: float) -> Polygon:
    """The camera's view on the LIDAR plane (``base_scan``): the wedge of the whole image out to ``max_range_m``."""
    cache = camera.__dict__.setdefault("_bound_cache", {})
    poly = cache.get(float(max_range_m))
    if poly is None:
        W = camera.info.width
        b_left, b_right = (float(b) for b in camera.column_bearings_scan(np.array([0.0, float(W)])))
        poly = _wedge_polygon(camera.apex_scan, b_left, b_right, 0.0, max_range_m)
        cache.clear()
        cache[float(max_range_m)] = poly
    return poly


def camera_bound_bearings(camera: CameraModel) -> tuple[float, float]:
    """``(bearing_right, bearing_left)`` of the image's edges about the apex in ``base_scan``."""
    b_left, b_right = (float(b) for b in camera.column_bearings_scan(np.array([0.0, float(camera.info.width)])))
    return b_right, b_left


def assign_points(
    points_scan: FloatArray,
    areas: Sequence[BoundingArea],
    exclusive: bool = True,
    range_tolerance: float = 0.25,
) -> NDArray[np.bool_]:
    """Which points lie in which areas: ``(N, 2)`` points in ``base_scan`` → ``(N, A)`` bool.

    Containment uses ``shapely.contains_xy`` (vectorised per area). With ``exclusive`` (improved mode)
    a point inside several areas goes to one only: the area whose expected range (its near range
    from the bottom edge, ``[near_lo·(1−tol), near_hi·(1+tol)]``) explains the point best; on a tie
    the area nearest the camera (smallest near range), then the one whose bisector is closest, then
    the higher confidence.
    Without ``exclusive`` (seed mode) a point may belong to several areas.
    """
    pts = np.asarray(points_scan, dtype=np.float64).reshape(-1, 2)
    A = len(areas)
    inside = np.zeros((len(pts), A), dtype=bool)
    if len(pts) == 0 or A == 0:
        return inside
    finite = np.all(np.isfinite(pts), axis=1)
    for k, area in enumerate(areas):
        inside[:, k] = shapely.contains_xy(area.polygon, pts[:, 0], pts[:, 1]) & finite
    if not exclusive:
        return inside
    multi = inside.sum(axis=1) > 1
    if not np.any(multi):
        return inside
    rows = np.flatnonzero(multi)
    sub = pts[rows]
    cost = np.full((len(rows), A), np.inf)
    for k, area in enumerate(areas):
        d = sub - area.apex[None, :]
        r = np.hypot(d[:, 0], d[:, 1])
        lo = area.near_range_lo * (1.0 - range_tolerance) if np.isfinite(area.near_range_lo) else 0.0
        hi = area.near_range_hi * (1.0 + range_tolerance) if np.isfinite(area.near_range_hi) else np.inf
        outside = np.maximum(lo - r, 0.0) + np.maximum(r - hi, 0.0)
        # Range mismatch dominates; then the nearest area; then the bisector's angular offset.
        near = area.near_range_m if np.isfinite(area.near_range_m) else 1e3
        off = np.abs(area.angular_offsets(sub))
        c = outside / np.maximum(r, 0.1) * 1e6 + near * 1e2 + off - 1e-6 * area.confidence
        cost[:, k] = np.where(inside[rows, k], c, np.inf)
    best = np.argmin(cost, axis=1)
    inside[rows] = False
    inside[rows, best] = True
    return inside


# ----------------------------------------------------------------------------------------------
# Seed-faithful projection (spec §1.2–1.4)
# ----------------------------------------------------------------------------------------------

SEED_CAM_HEIGHT = 0.20
SEED_LIDAR_HEIGHT = 0.16
SEED_H = SEED_CAM_HEIGHT - SEED_LIDAR_HEIGHT  # 0.04 m
SEED_IMAGE_WIDTH = 640 * 1.05  # 672
SEED_IMAGE_HEIGHT = 481 * 1.05  # 505.05
SEED_FX, SEED_FY, SEED_CX, SEED_CY = 565.1448, 566.1120, 322.4309, 255.4085
SEED_WIDEN = 1.05


def seed_project_points(xy: FloatArray) -> FloatArray:
    """The original ``project_point`` on ``(N, 2)`` pixel coordinates → ``(N, 2)`` LIDAR-plane points.

    ``u = (x − cx)/fx``, ``v = (min(y, cy − 1) − cy)/fy``, ``X = h/(−v)``, ``Y = −u·X``
    (``X ≤ h·fy = 22.64 m``).
    """
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    u = (xy[:, 0] - SEED_CX) / SEED_FX
    v = (np.minimum(xy[:, 1], SEED_CY - 1.0) - SEED_CY) / SEED_FY
    X = SEED_H / (-v)
    return np.stack([X, -u * X], axis=1)


@dataclass(eq=False)
class SeedProjection:
    """The original's projection of one box: the quadrilateral and its centre line (robot = LIDAR frame)."""

    detection: Detection | None
    vertices: FloatArray  # (4, 2) near-left, near-right, far-right, far-left
    polygon: Polygon
    points: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))  # (K, 2) LIDAR points it received

    @property
    def near_midpoint(self) -> FloatArray:
        return 0.5 * (self.vertices[0] + self.vertices[1])

    @property
    def far_midpoint(self) -> FloatArray:
        return 0.5 * (self.vertices[2] + self.vertices[3])

    def bisector_distance(self, points: FloatArray) -> FloatArray:
        a, b = self.near_midpoint, self.far_midpoint
        d = b - a
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2) - a
        return np.abs(p[:, 0] * d[1] - p[:, 1] * d[0]) / max(float(np.linalg.norm(d)), 1e-12)


def seed_projection(x1: float, y1: float, x2: float, y2: float, det: Detection | None = None) -> SeedProjection:
    """Project one box as the original did: rows flipped (``y' = 505.05 − y``), ``x2' = 1.05·x2``."""
    y1f, y2f = SEED_IMAGE_HEIGHT - y1, SEED_IMAGE_HEIGHT - y2
    x2w = SEED_WIDEN * x2
    corners = np.array([[x1, y2f], [x2w, y2f], [x2w, y1f], [x1, y1f]])
    verts = seed_project_points(corners)
    return SeedProjection(det, verts, Polygon(verts))


def seed_camera_projection() -> SeedProjection:
    """The original's camera bound: the unflipped image corners (0,0), (672,0), (672,505.05), (0,505.05)."""
    corners = np.array([[0.0, 0.0], [SEED_IMAGE_WIDTH, 0.0], [SEED_IMAGE_WIDTH, SEED_IMAGE_HEIGHT], [0.0, SEED_IMAGE_HEIGHT]])
    verts = seed_project_points(corners)
    return SeedProjection(None, verts, Polygon(verts))


def seed_camera_angles() -> tuple[float, float]:
    """``(cam_angle_min, cam_angle_max)`` ≈ (−0.5539, +0.5185) rad."""
    v = seed_camera_projection().vertices
    a = np.arctan2(v[:, 1], v[:, 0])
    return float(a.min()), float(a.max())


SEED_CAMERA_SIZE = (640, 480)  # the original camera's image, the pixels its constants are in


def seed_bounding_areas(detections: Detections) -> list[SeedProjection]:
    """The original's areas, from the integer ``/yolo_boxes`` matrix (one per box, in order).

    The original's constants are in the 640×480 camera image's pixels, so boxes of an image rendered at
    another size (the app renders 320×240 by default) are first scaled to 640×480, as the original's
    YOLO node would have reported them.
    """
    out = []
    sx, sy = _box_scale(detections, *SEED_CAMERA_SIZE)
    seen = Detections(detections.stamp, *SEED_CAMERA_SIZE, tuple(_scale_box(b, sx, sy) for b in detections.boxes))
    for det, row in zip(detections.boxes, seen.yolo_boxes()):
        x1, y1, x2, y2 = (float(v) for v in row[:4])
        out.append(seed_projection(x1, y1, x2, y2, det))
    return out


def seed_assign_points(points: FloatArray, projections: Sequence[SeedProjection]) -> NDArray[np.bool_]:
    """``(N, 2)`` points → ``(N, A)``: strict containment, a point may be in several areas."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    out = np.zeros((len(pts), len(projections)), dtype=bool)
    for k, p in enumerate(projections):
        if len(pts):
            out[:, k] = shapely.contains_xy(p.polygon, pts[:, 0], pts[:, 1])
    return out


def seed_scan_points(ranges: FloatArray, angle_min: float, angle_increment: float) -> FloatArray:
    """The original's LIDAR points: every non-inf range inside the camera's strict angle limits → ``(M, 2)``."""
    r = np.asarray(ranges, dtype=np.float64)
    theta = angle_min + angle_increment * np.arange(len(r))
    a_min, a_max = seed_camera_angles()
    keep = ~np.isinf(r) & ~np.isnan(r) & (theta > a_min) & (theta < a_max)
    return np.stack([r[keep] * np.cos(theta[keep]), r[keep] * np.sin(theta[keep])], axis=1)
