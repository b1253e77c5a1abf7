"""Detection boxes projected onto the LIDAR plane ("bounding areas", paper §2.5.2).

Improved geometry (default), on the half-lines of the image columns (:class:`~app.ocslam.camera.CameraModel`):
a box ``(x1, y1, x2, y2)`` becomes the wedge between the half-lines of its left and right edges,
starting at the *near range* where the ray through its bottom edge meets the floor (``z = 0``), and
ending at ``max_range_m``. The *bisector* is the half-line of the box's centre column. All areas are
shapely polygons in the ``base_scan`` frame (2D, metres). :func:`assign_points` gives each LIDAR point
to the area that explains it best.

The original implementation's formulas (seed mode) are in :mod:`app.ocslam.seed_projection`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import shapely
from numpy.typing import NDArray
from shapely.geometry import Polygon

from app.ocslam.camera import CameraModel
from app.ocslam.messages import Detection, Detections

FloatArray = NDArray[np.float64]

#: Points of a wedge's far arc.
_ARC_SEGMENTS = 12


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
    # an annular sector (or a fan from the apex) narrower than a half-turn with distinct arcs is a simple
    # ring: valid by construction, so GEOS' validity test (a third of the wedge's cost) is skipped
    simple = 1e-3 < span < np.pi - 1e-3 and r_far - max(r_near, 0.0) > 1e-3 and np.all(np.isfinite(ring))
    if not simple and not poly.is_valid:
        poly = shapely.make_valid(poly)
        if not isinstance(poly, Polygon):
            poly = Polygon(ring).buffer(0)
    return poly


def box_scale(detections: Detections, width: float, height: float) -> tuple[float, float]:
    """``(sx, sy)`` from the detections' image size to ``width × height`` (1, 1 if the size is unknown)."""
    if detections.image_width > 0 and detections.image_height > 0:
        return width / detections.image_width, height / detections.image_height
    return 1.0, 1.0


def scale_box(det: Detection, sx: float, sy: float) -> Detection:
    """``det`` with its corners scaled by ``(sx, sy)`` (the same object when both are 1)."""
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
    return _areas_from_boxes([det], camera, max_range_m, bottom_margin_px, edge_margin_px, near_tolerance)[0]


def _areas_from_boxes(
    dets: Sequence[Detection],
    camera: CameraModel,
    max_range_m: float,
    bottom_margin_px: float,
    edge_margin_px: float,
    near_tolerance: float,
) -> list[BoundingArea | None]:
    """:func:`area_from_box` for every box of a frame, with one camera computation for all of them."""
    W, H = camera.info.width, camera.info.height
    boxes: list[tuple[int, float, float, float, float]] = []
    for i, det in enumerate(dets):
        vals = np.array([det.x1, det.y1, det.x2, det.y2], dtype=np.float64)
        if not np.all(np.isfinite(vals)):
            continue
        x1, x2 = np.clip(sorted((vals[0], vals[2])), 0.0, W)
        y1, y2 = np.clip(sorted((vals[1], vals[3])), 0.0, H)
        if x2 - x1 < 1.0 or y2 - y1 < 1.0:
            continue
        boxes.append((i, float(x1), float(y1), float(x2), float(y2)))
    out: list[BoundingArea | None] = [None] * len(dets)
    if boxes:
        xs = np.array([[x1, x2, 0.5 * (x1 + x2)] for _d, x1, _y1, x2, _y2 in boxes])
        bearings = camera.column_bearings_scan(xs.reshape(-1)).reshape(-1, 3)
        rows = np.array([[[xc, y2], [xc, min(y2 + bottom_margin_px, H)], [xc, max(y2 - bottom_margin_px, 0.0)]]
                         for (_d, _x1, _y1, _x2, y2), xc in zip(boxes, xs[:, 2])])
        ranges = camera.ground_ranges(rows.reshape(-1, 2)).reshape(-1, 3)
        apex = camera.apex_scan
        for k, (i, x1, y1, x2, y2) in enumerate(boxes):
            truncated = {
                "left": bool(x1 <= edge_margin_px),
                "right": bool(x2 >= W - edge_margin_px),
                "top": bool(y1 <= edge_margin_px),
                "bottom": bool(y2 >= H - edge_margin_px),
            }
            b_left, b_right, b_center = (float(b) for b in bearings[k])
            near, near_lo, near_hi = (float(r) for r in ranges[k])
            if truncated["bottom"] or not np.isfinite(near_lo):
                near_lo = 0.0  # the floor contact is not visible: no lower bound
            near_lo = min(near_lo, max_range_m)
            r_poly = max(near_lo * (1.0 - near_tolerance), 0.0) if np.isfinite(near_lo) else 0.0
            r_poly = min(r_poly, 0.95 * max_range_m)
            poly = _wedge_polygon(apex, b_left, b_right, r_poly, max_range_m)
            direction = np.array([np.cos(b_center), np.sin(b_center)])
            out[i] = BoundingArea(
                detection=dets[i],
                polygon=poly,
                apex=apex.copy(),
                bearing_left=b_left,
                bearing_right=b_right,
                bearing_center=b_center,
                near_range_m=near,
                near_range_lo=near_lo,
                near_range_hi=near_hi,
                far_range_m=float(max_range_m),
                bisector=np.stack([apex, apex + max_range_m * direction]),
                truncated=truncated,
                box_px=np.array([x1, y1, x2, y2], dtype=np.float64),
            )
    return out


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
        sx, sy = box_scale(detections, camera.info.width, camera.info.height)
    else:
        boxes = detections
    scaled = [scale_box(det, sx, sy) for det in boxes]
    out = []
    for det, a in zip(boxes, _areas_from_boxes(scaled, camera, max_range_m, bottom_margin_px, edge_margin_px,
                                               near_tolerance)):
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
        # Range mismatch dominates; then the nearest area; then the bisector's angular offset.
        near = area.near_range_m if np.isfinite(area.near_range_m) else 1e3
        off = np.abs(area.angular_offsets(sub))
        c = _range_miss(sub, area, range_tolerance) * 1e6 + near * 1e2 + off - 1e-6 * area.confidence
        cost[:, k] = np.where(inside[rows, k], c, np.inf)
    best = np.argmin(cost, axis=1)
    inside[rows] = False
    inside[rows, best] = True
    return inside


def _range_miss(points_scan: FloatArray, area: BoundingArea, tolerance: float) -> FloatArray:
    """``(N,)`` how far each point's range about the apex lies outside ``[near_lo·(1−tol), near_hi·(1+tol)]``
    (an unknown bound: no limit), relative to the point's range."""
    d = np.asarray(points_scan, dtype=np.float64).reshape(-1, 2) - area.apex[None, :]
    r = np.hypot(d[:, 0], d[:, 1])
    lo = area.near_range_lo * (1.0 - tolerance) if np.isfinite(area.near_range_lo) else 0.0
    hi = area.near_range_hi * (1.0 + tolerance) if np.isfinite(area.near_range_hi) else np.inf
    return (np.maximum(lo - r, 0.0) + np.maximum(r - hi, 0.0)) / np.maximum(r, 0.1)


def range_deviation(points_scan: FloatArray, area: BoundingArea) -> FloatArray:
    """``(N,)`` how far each point's range about the area's apex lies outside the range its bottom edge
    gives (``[near_lo, near_hi]``), relative to the point's range (0 inside; ``nan`` when the bottom edge
    gives no range: cut by the border, or at or above the horizon)."""
    if not area.bottom_reliable or not np.isfinite(area.near_range_lo):
        return np.full(len(np.asarray(points_scan).reshape(-1, 2)), np.nan)
    return _range_miss(points_scan, area, 0.0)


def contest_by_range(points_scan: FloatArray, areas: Sequence[BoundingArea], member: NDArray[np.bool_],
                     slack: float) -> NDArray[np.bool_]:
    """Points inside several areas' wedges go only to the areas whose bottom-edge range explains them:
    an area loses a point whose range deviates from its own by more than ``slack`` (relative) beyond
    the best-explaining area's (:func:`range_deviation`). A table's leg in front of a chair seen behind
    it stays the table's; areas whose bottom edge gives no range keep their points. ``member``:
    ``(N, A)`` as :func:`assign_points` without ``exclusive``; returns a copy."""
    out = np.array(member, dtype=bool, copy=True)
    multi = np.flatnonzero(out.sum(axis=1) > 1)
    if len(multi) == 0:
        return out
    sub = np.asarray(points_scan, dtype=np.float64).reshape(-1, 2)[multi]
    dev = np.column_stack([range_deviation(sub, a) for a in areas])
    dev = np.where(out[multi], dev, np.nan)  # nan: no range, or not a member: never loses
    best = np.min(np.where(np.isnan(dev), np.inf, dev), axis=1)
    out[multi] &= ~(dev > best[:, None] + slack)
    return out
