"""The original implementation's projection of detection boxes (seed mode, spec §1.2–1.4).

Deliberately kept as the original computed it: the camera 4 cm above the LIDAR at its origin, the
calibrated K, the 672×505.05 image with flipped rows, the right edge widened by 1.05, ranges clamped
at 22.64 m, strict containment, and a point may belong to several areas. All geometry in the LIDAR
frame, which the original takes as the camera's and the robot's. The improved geometry is
:mod:`app.ocslam.projection`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import shapely
from numpy.typing import NDArray
from shapely.geometry import Polygon

from app.ocslam.messages import Detection, Detections
from app.ocslam.projection import box_scale, scale_box

FloatArray = NDArray[np.float64]

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
    sx, sy = box_scale(detections, *SEED_CAMERA_SIZE)
    seen = Detections(detections.stamp, *SEED_CAMERA_SIZE, tuple(scale_box(b, sx, sy) for b in detections.boxes))
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
