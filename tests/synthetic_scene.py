"""Synthetic scenes for the Consciousness tests: analytic LIDAR ray casting and boxes projected with K.

Shapes live in the ``map`` frame: vertical cylinders and oriented boxes with a height range.
:func:`raycast` builds a LaserScan (nearest hit per beam among the shapes that cut the LIDAR plane);
:func:`detect` projects a shape's 3D outline with the camera model into a detection box (clipped to
the image), optionally checking that the shape's centre is not hidden by a nearer shape.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.ocslam.camera import CameraModel
from app.ocslam.messages import CLASS_INDEX, CameraInfo, Detection, Detections, LaserScan
from app.ocslam.se2 import Pose2


@dataclass(frozen=True)
class Cylinder:
    x: float
    y: float
    r: float
    z0: float = 0.0
    z1: float = 1.0


@dataclass(frozen=True)
class Box:
    x: float
    y: float
    sx: float
    sy: float
    yaw: float = 0.0
    z0: float = 0.0
    z1: float = 1.0

    def corners2d(self) -> np.ndarray:
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        hx, hy = self.sx / 2, self.sy / 2
        loc = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
        return loc @ np.array([[c, -s], [s, c]]).T + np.array([self.x, self.y])


def default_camera(width: int = 640, height: int = 480, hfov: float = 1.04) -> CameraModel:
    """TurtleBot3-like mount: camera 0.19 m high at the axle, LIDAR 0.173 m high 3.2 cm behind."""
    return CameraModel.from_mount(CameraInfo.from_fov(width, height, hfov))


def _ray_hits(shape, origins: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Distance along each ray (origin (2,), dirs (N, 2) unit) to the shape, inf if missed."""
    o = origins
    if isinstance(shape, Cylinder):
        c = np.array([shape.x, shape.y])
        oc = o - c
        b = dirs @ oc
        cc = oc @ oc - shape.r**2
        disc = b**2 - cc
        t = -b - np.sqrt(np.maximum(disc, 0.0))
        t = np.where((disc >= 0) & (t > 1e-9), t, np.inf)
        if cc < 0:  # origin inside
            t = np.full(len(dirs), np.inf)
        return t
    pts = shape.corners2d()
    out = np.full(len(dirs), np.inf)
    for i in range(4):
        a, b = pts[i], pts[(i + 1) % 4]
        e = b - a
        denom = dirs[:, 0] * (-e[1]) - dirs[:, 1] * (-e[0])
        w = a - o
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (w[0] * (-e[1]) - w[1] * (-e[0])) / denom
            s = (dirs[:, 0] * w[1] - dirs[:, 1] * w[0]) / denom
        ok = (np.abs(denom) > 1e-12) & (t > 1e-9) & (s >= 0) & (s <= 1)
        out = np.where(ok & (t < out), t, out)
    return out


def raycast(
    shapes,
    T_map_base: Pose2,
    camera: CameraModel,
    beams: int = 360,
    range_min: float = 0.12,
    range_max: float = 3.5,
    noise: float = 0.0,
    rng: np.random.Generator | None = None,
    stamp: float = 0.0,
) -> LaserScan:
    """A LaserScan in ``base_scan`` of the shapes that cut the LIDAR plane."""
    T_map_scan = T_map_base @ camera.T_base_scan_2d
    z = camera.lidar_height
    angles = -np.pi + 2 * np.pi * np.arange(beams) / beams
    dirs_map = np.stack([np.cos(angles + T_map_scan.yaw), np.sin(angles + T_map_scan.yaw)], axis=1)
    o = np.array([T_map_scan.x, T_map_scan.y])
    r = np.full(beams, np.inf)
    for sh in shapes:
        if not (sh.z0 <= z <= sh.z1):
            continue
        r = np.minimum(r, _ray_hits(sh, o, dirs_map))
    if noise > 0:
        rng = rng or np.random.default_rng(0)
        r = r + rng.normal(0.0, noise, beams)
    r = np.where((r > range_max) | (r < range_min), np.inf, r)
    return LaserScan(stamp=stamp, angle_min=-np.pi, angle_increment=2 * np.pi / beams, range_min=range_min, range_max=range_max, ranges=r)


def outline3d(shape, n: int = 24) -> np.ndarray:
    """(M, 3) points on the shape's surface outline (map frame): its footprint ring at the bottom and top."""
    if isinstance(shape, Cylinder):
        t = np.linspace(0, 2 * np.pi, n, endpoint=False)
        ring = np.stack([shape.x + shape.r * np.cos(t), shape.y + shape.r * np.sin(t)], axis=1)
    else:
        c = shape.corners2d()
        k = max(n // 4, 1)
        f = np.linspace(0.0, 1.0, k, endpoint=False)[:, None]
        ring = np.vstack([c[i] + f * (c[(i + 1) % 4] - c[i]) for i in range(4)])
    lo = np.hstack([ring, np.full((len(ring), 1), shape.z0)])
    hi = np.hstack([ring, np.full((len(ring), 1), shape.z1)])
    return np.vstack([lo, hi])


def project_shapes(parts, T_map_base: Pose2, camera: CameraModel) -> tuple[float, float, float, float] | None:
    """Pixel box ``(x1, y1, x2, y2)`` around the projection of one or several shapes, clipped to the image.

    Parts of the outline behind the camera push the box to the image border on their side (a partial
    view); ``None`` if nothing is in front of the camera or the box is empty.
    """
    pts = np.vstack([outline3d(p, n=96) for p in parts])
    # densify the vertical edges so that clipping at the image border is faithful
    xy_base = T_map_base.inverse().transform_points(pts[:, :2])
    p3 = np.hstack([xy_base, pts[:, 2:3]])
    uv, depth = camera.project(p3)
    front = depth > 0.05
    if not np.any(front):
        return None
    W, H = camera.info.width, camera.info.height
    x1, y1 = uv[front].min(axis=0)
    x2, y2 = uv[front].max(axis=0)
    behind = ~front
    if np.any(behind):
        lateral = p3[behind] - camera.center_base[None, :]
        if np.any(lateral[:, 1] > 0):  # behind and to the left: the object continues past the left border
            x1 = 0.0
        if np.any(lateral[:, 1] < 0):
            x2 = float(W)
    x1, x2 = np.clip([x1, x2], 0, W)
    y1, y2 = np.clip([y1, y2], 0, H)
    if x2 - x1 < 2 or y2 - y1 < 2:
        return None
    return float(x1), float(y1), float(x2), float(y2)


def detection(
    label: str, parts, T_map_base: Pose2, camera: CameraModel, confidence: float = 0.9, pad_px: float = 0.0, pad_y_px: float = 0.0
) -> Detection | None:
    """The detection box of a shape (or list of shapes), widened by ``pad_px`` left/right and ``pad_y_px`` up/down."""
    box = project_shapes(parts if isinstance(parts, (list, tuple)) else [parts], T_map_base, camera)
    if box is None:
        return None
    x1, y1, x2, y2 = box
    W, H = camera.info.width, camera.info.height
    return Detection(max(x1 - pad_px, 0), max(y1 - pad_y_px, 0), min(x2 + pad_px, W), min(y2 + pad_y_px, H), CLASS_INDEX[label], confidence)


def detections(boxes, camera: CameraModel, stamp: float = 0.0) -> Detections:
    return Detections(stamp, camera.info.width, camera.info.height, tuple(b for b in boxes if b is not None))


def table(x: float, y: float, length: float = 1.8, width: float = 1.0, height: float = 0.74, leg: float = 0.1, yaw: float = 0.0):
    """A table: four legs (boxes) plus a top (above the LIDAR plane). Returns (legs, top)."""
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.array([[c, -s], [s, c]])
    legs = []
    for dx in (-(length - leg) / 2, (length - leg) / 2):
        for dy in (-(width - leg) / 2, (width - leg) / 2):
            p = R @ np.array([dx, dy]) + np.array([x, y])
            legs.append(Box(p[0], p[1], leg, leg, yaw, 0.0, height))
    top = Box(x, y, length, width, yaw, height - 0.04, height)
    return legs, top
