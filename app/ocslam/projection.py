"""Detection boxes projected onto the LIDAR plane ("bounding areas", paper §2.5.2).

Improved geometry (default), on the half-lines of the image columns (:class:`~app.ocslam.camera.CameraModel`):
a box ``(x1, y1, x2, y2)`` becomes the wedge between the half-lines of its left and right edges,
starting at the *near range* where the ray through its bottom edge meets the floor (``z = 0``), and
ending at ``max_range_m``. The *bisector* is the half-line of the box's centre column. All areas are
shapely polygons in the ``base_scan`` frame (2D, metres), built when first asked for (the fusion itself
tests membership by bearing and range, :func:`_in_wedges`). Which area owns which LIDAR point is
:mod:`app.ocslam.point_ownership`.

The original implementation's formulas (seed mode) are in :mod:`app.ocslam.seed_projection`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property

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

    ``polygon``: the wedge (built on first use, from the fields below); ``apex``: (2,) its tip;
    ``bearing_left``/``bearing_right``/``bearing_center``: bearings (rad) of the half-lines through the
    box's left edge, right edge and centre column;
    ``near_range_m``: distance from the apex to the floor point under the box's bottom edge
    (``inf`` if the bottom edge is at or above the horizon); ``near_range_lo``/``near_range_hi``: the same
    with the bottom edge moved down/up by the pixel margin; ``far_range_m``: the wedge's far arc;
    ``bisector``: (2, 2) segment ``[apex, apex + far·dir_center]``; ``truncated``: which box edges touch
    the image border (``left``, ``right``, ``top``, ``bottom``); ``box_px``: the box clipped to the image,
    in the camera's pixel grid; ``points``: the LIDAR points it received in the last update;
    ``polygon_near_m``: the range where the polygon starts (its near arc; 0: a fan from the apex).
    """

    detection: Detection
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
    polygon_near_m: float = 0.0

    @cached_property
    def polygon(self) -> Polygon:
        """The wedge as a shapely polygon (``base_scan``)."""
        return _wedge_polygon(self.apex, self.bearing_left, self.bearing_right, self.polygon_near_m, self.far_range_m)

    @cached_property
    def _wedge_test(self) -> _WedgeTest | None:
        """The constants of the exact membership test of :func:`_in_wedges` (``None``: not a simple wedge)."""
        return _wedge_test(self.apex, self.bearing_left, self.bearing_right, self.polygon_near_m, self.far_range_m)

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
    def columns(self) -> tuple[float, float]:
        """``(x1, x2)``: the box's image columns (camera pixels, clipped)."""
        return float(self.box_px[0]), float(self.box_px[2])

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
    if isinstance(a, float) and isinstance(b, float):  # scalars: Python's float ``%`` is numpy's, with less overhead
        return (a - b + math.pi) % (2.0 * math.pi) - math.pi
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
    # a simple wedge's ring is valid by construction, so GEOS' validity test (a third of the wedge's
    # cost) is skipped
    simple = _simple_wedge(span, r_near, r_far) and np.all(np.isfinite(ring))
    if not simple and not poly.is_valid:
        poly = shapely.make_valid(poly)
        if not isinstance(poly, Polygon):
            poly = Polygon(ring).buffer(0)
    return poly


def _simple_wedge(span: float, r_near: float, r_far: float) -> bool:
    """An annular sector (or a fan from the apex) narrower than a half-turn with distinct arcs: its ring
    is simple, so valid by construction (and convex but for the near arc)."""
    return 1e-3 < span < np.pi - 1e-3 and r_far - max(r_near, 0.0) > 1e-3


@dataclass(slots=True)
class _WedgeTest:
    """A simple wedge polygon (:func:`_wedge_polygon`) as bearing and range bounds about its apex.

    ``t0``/``span``: the bearing of its right edge and the angle to its left edge; ``cos_m``/``sin_m``:
    ``(S,)`` the directions of its arc chords' normals (at the chords' mid bearings); ``far_d``/``near_d``:
    the distance of its far and near chords from the apex (``near_d`` ``None``: a fan from the apex)."""

    apex: tuple[float, float]
    t0: float
    span: float
    cos_m: FloatArray
    sin_m: FloatArray
    far_d: float
    near_d: float | None


#: The arc chords' mid bearings, in chord widths from the right edge.
_CHORD_MIDS = np.arange(_ARC_SEGMENTS, dtype=np.float64) + 0.5


def _wedge_test(apex: FloatArray, b_left: float, b_right: float, r_near: float, r_far: float) -> _WedgeTest | None:
    """:class:`_WedgeTest` of :func:`_wedge_polygon`'s polygon; ``None`` if it is not a simple wedge.

    Its arc vertices are at ``b_right + np.linspace(0, span, S + 1)``: chords of width ``span / S``
    (to the last bit, far below ``_WEDGE_EPS``)."""
    span = float(_angle_diff(b_left, b_right))
    ax, ay = float(apex[0]), float(apex[1])
    if not (_simple_wedge(span, r_near, r_far) and math.isfinite(ax) and math.isfinite(ay) and math.isfinite(b_right)
            and math.isfinite(r_near) and math.isfinite(r_far)):
        return None
    step = span / _ARC_SEGMENTS
    m = _CHORD_MIDS * step + b_right
    ch = math.cos(0.5 * step)
    return _WedgeTest((ax, ay), b_right, span, np.cos(m), np.sin(m), r_far * ch, r_near * ch if r_near > 1e-6 else None)


#: Points closer than this (m, rad) to a wedge's outline are tested on its polygon (shapely).
_WEDGE_EPS = 1e-8


def _in_wedges(pts: FloatArray, tests: Sequence[_WedgeTest]) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """``(N, 2)`` finite points, ``A`` wedges with one apex → ``(N, A)`` strictly inside, and ``(N, A)``
    too near the outline to tell (within ``_WEDGE_EPS``, or on the apex; the polygon decides those).

    The polygon is convex but for its near arc: a point is inside when its bearing about the apex lies
    between the edges' and, for every arc chord, its projection on the chord's normal is short of the
    far chord's distance; and (an annular sector) beyond the near chord's distance for some chord. The
    smallest of these margins is positive inside, negative outside.
    """
    ax, ay = tests[0].apex
    dx, dy = pts[:, 0] - ax, pts[:, 1] - ay
    theta = np.arctan2(dy, dx)
    inside = np.zeros((len(pts), len(tests)), dtype=bool)
    unsure = np.zeros((len(pts), len(tests)), dtype=bool)
    for k, w in enumerate(tests):
        a = (theta - w.t0 + np.pi) % (2.0 * np.pi) - np.pi  # bearing from the right edge
        rows = np.flatnonzero((a > -_WEDGE_EPS) & (a < w.span + _WEDGE_EPS))  # the others: surely outside
        if len(rows) == 0:
            continue
        a, x, y = a[rows], dx[rows], dy[rows]
        proj = (x[:, None] * w.cos_m[None, :] + y[:, None] * w.sin_m[None, :]).max(axis=1)
        margin = np.minimum(np.minimum(a, w.span - a), w.far_d - proj)
        if w.near_d is not None:
            margin = np.minimum(margin, proj - w.near_d)
        inside[rows, k] = margin > 0.0
        unsure[rows, k] = (np.abs(margin) < _WEDGE_EPS) | (np.abs(x) + np.abs(y) < _WEDGE_EPS)
    return inside, unsure


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


def _clip(v: float, hi: float) -> float:
    """``np.clip(v, 0, hi)`` of a finite float (numpy's comparisons, so ``-0.0`` clips to ``0.0`` as there)."""
    v = v if v > 0.0 else 0.0
    return float(v if v < hi else hi)


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
        x1, y1, x2, y2 = float(det.x1), float(det.y1), float(det.x2), float(det.y2)
        if not (math.isfinite(x1) and math.isfinite(y1) and math.isfinite(x2) and math.isfinite(y2)):
            continue
        x1, x2 = (x1, x2) if x1 <= x2 else (x2, x1)
        y1, y2 = (y1, y2) if y1 <= y2 else (y2, y1)
        x1, x2, y1, y2 = _clip(x1, W), _clip(x2, W), _clip(y1, H), _clip(y2, H)
        if x2 - x1 < 1.0 or y2 - y1 < 1.0:
            continue
        boxes.append((i, x1, y1, x2, y2))
    out: list[BoundingArea | None] = [None] * len(dets)
    if not boxes:
        return out
    n = len(boxes)
    xs = np.empty((n, 3))  # left, right, centre column
    rows = np.empty((n, 3, 2))  # the centre column at the bottom edge, moved down, moved up
    for k, (_i, x1, _y1, x2, y2) in enumerate(boxes):
        xc = 0.5 * (x1 + x2)
        xs[k] = (x1, x2, xc)
        rows[k] = ((xc, y2), (xc, min(y2 + bottom_margin_px, H)), (xc, max(y2 - bottom_margin_px, 0.0)))
    bearings = camera.column_bearings_scan(xs.reshape(-1)).reshape(-1, 3).tolist()
    ranges = camera.ground_ranges(rows.reshape(-1, 2)).reshape(-1, 3).tolist()
    apex = camera.apex_scan
    ax, ay = float(apex[0]), float(apex[1])
    for k, (i, x1, y1, x2, y2) in enumerate(boxes):
        truncated = {
            "left": x1 <= edge_margin_px,
            "right": x2 >= W - edge_margin_px,
            "top": y1 <= edge_margin_px,
            "bottom": y2 >= H - edge_margin_px,
        }
        b_left, b_right, b_center = bearings[k]
        near, near_lo, near_hi = ranges[k]
        if truncated["bottom"] or not math.isfinite(near_lo):
            near_lo = 0.0  # the floor contact is not visible: no lower bound
        near_lo = min(near_lo, max_range_m)
        r_poly = max(near_lo * (1.0 - near_tolerance), 0.0) if math.isfinite(near_lo) else 0.0
        r_poly = min(r_poly, 0.95 * max_range_m)
        out[i] = BoundingArea(
            detection=dets[i],
            apex=apex.copy(),
            bearing_left=b_left,
            bearing_right=b_right,
            bearing_center=b_center,
            near_range_m=near,
            near_range_lo=near_lo,
            near_range_hi=near_hi,
            far_range_m=float(max_range_m),
            bisector=np.array([[ax, ay], [ax + max_range_m * math.cos(b_center), ay + max_range_m * math.sin(b_center)]]),
            truncated=truncated,
            box_px=np.array([x1, y1, x2, y2], dtype=np.float64),
            polygon_near_m=r_poly,
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
    """``(bearing_right, bearing_left)`` of the image's edges about the apex in ``base_scan`` (cached on
    the camera for its image width, as :func:`camera_bound`)."""
    cache = camera.__dict__.setdefault("_bound_bearings_cache", {})
    key = float(camera.info.width)
    out = cache.get(key)
    if out is None:
        b_left, b_right = (float(b) for b in camera.column_bearings_scan(np.array([0.0, key])))
        out = (b_right, b_left)
        cache.clear()
        cache[key] = out
    return out
