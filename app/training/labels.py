"""Detector labels from the simulator's segmentation mask.

A label is the tight box of an object's *visible* pixels (so truncated and partly occluded objects get
the box a detector must predict). It is kept when enough of the object is visible:

- ``visible_pixels ≥ min_pixels`` (the object covers enough of the image), and
- ``visible_fraction ≥ min_visible_fraction``, where ``visible_fraction = visible_pixels / full_pixels``
  and ``full_pixels`` is the object's *unoccluded, untruncated* silhouette area at the same pixel scale
  (rendered alone on an image plane that extends past the frame, see :mod:`app.training.silhouettes`), and
- ``in_frame_fraction ≥ min_in_frame_fraction``: at least half of the silhouette is inside the frame
  (an object cut by the sides or the bottom to less than half of itself, like one table leg or a sofa
  filling the view from 20 cm, has lost what tells it apart), and
- the box's shorter side ≥ ``min_box_px``.

Objects that are visible but fail these tests are returned as *ignore* regions: they are not training
labels (a sliver of a table leg is no "table"), and the benchmark does not count a detection on them as
a false positive (COCO ``iscrowd``).

``full_pixels`` comes from :class:`app.training.silhouettes.SilhouetteRenderer` (each object rendered alone
at the same pixel scale). This module is numpy only.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "LabelFilter",
    "ObjectLabel",
    "visible_boxes",
    "make_labels",
    "label_kept",
    "yolo_lines",
    "object_boxes",
    "may_be_labelled",
]


@dataclass(frozen=True, slots=True)
class LabelFilter:
    """When a visible object becomes a label (defaults measured to help: see docs/detector.md).

    ``min_pixels`` and ``min_box_px`` are measured in the image scaled to ``reference_width`` (the
    detector's 224-px input), so the same objects are labelled whatever the render size.
    """

    min_pixels: float = 30.0
    min_visible_fraction: float = 0.35
    min_box_px: float = 8.0
    reference_width: int = 224
    min_in_frame_fraction: float = 0.5

    def scaled(self, image_width: int) -> tuple[float, float]:
        """``(min_pixels, min_box_px)`` in pixels of an image ``image_width`` wide."""
        k = image_width / float(self.reference_width)
        return self.min_pixels * k * k, self.min_box_px * k


@dataclass(frozen=True, slots=True)
class ObjectLabel:
    """One object's box in an image: pixel edges ``x1 ≤ x < x2``, ``y1 ≤ y < y2`` (origin top-left)."""

    object_id: int
    class_id: int
    x1: int
    y1: int
    x2: int
    y2: int
    visible_pixels: int
    full_pixels: int
    keep: bool
    in_frame_pixels: int = -1  # unoccluded pixels inside the frame (-1: unknown, taken as full_pixels)

    @property
    def visible_fraction(self) -> float:
        """Visible share of the whole silhouette (occlusion and truncation together)."""
        return self.visible_pixels / self.full_pixels if self.full_pixels > 0 else 1.0

    @property
    def in_frame_fraction(self) -> float:
        """Share of the silhouette inside the frame (1 − truncation by the side and bottom edges)."""
        inside = self.full_pixels if self.in_frame_pixels < 0 else self.in_frame_pixels
        return min(1.0, inside / self.full_pixels) if self.full_pixels > 0 else 1.0

    @property
    def width(self) -> int:
        return self.x2 - self.x1

    @property
    def height(self) -> int:
        return self.y2 - self.y1


def visible_boxes(segmentation: NDArray[np.integer]) -> dict[int, tuple[int, int, int, int, int]]:
    """``(H, W)`` int mask of object ids (``-1`` or any negative: no object) →
    ``{id: (x1, y1, x2, y2, pixel_count)}`` with exclusive ``x2, y2``. Vectorised (one sort)."""
    seg = np.asarray(segmentation)
    if seg.ndim != 2:
        raise ValueError(f"expected an (H, W) segmentation mask, got shape {seg.shape}")
    flat = seg.ravel()
    idx = np.flatnonzero(flat >= 0)
    if idx.size == 0:
        return {}
    ids = flat[idx]
    order = np.argsort(ids, kind="stable")
    ids, idx = ids[order], idx[order]
    rows, cols = np.divmod(idx, seg.shape[1])
    uniq, start, counts = np.unique(ids, return_index=True, return_counts=True)
    x1 = np.minimum.reduceat(cols, start)
    x2 = np.maximum.reduceat(cols, start) + 1
    y1 = np.minimum.reduceat(rows, start)
    y2 = np.maximum.reduceat(rows, start) + 1
    return {
        int(u): (int(a), int(b), int(c), int(d), int(n)) for u, a, b, c, d, n in zip(uniq, x1, y1, x2, y2, counts)
    }


def make_labels(
    segmentation: NDArray[np.integer],
    class_of: Mapping[int, int],
    full_pixels: Mapping[int, int],
    filt: LabelFilter = LabelFilter(),
    in_frame_pixels: Mapping[int, int] | None = None,
    boxes: Mapping[int, tuple[int, int, int, int, int]] | None = None,
) -> list[ObjectLabel]:
    """Labels (kept or ignore) for every classified object visible in ``segmentation``.

    ``class_of`` maps object id → class index (ids not in it, e.g. walls or distractors, are skipped);
    ``full_pixels`` maps object id → unoccluded silhouette area (missing: the visible area, i.e. fraction 1);
    ``in_frame_pixels`` → the part of it inside the frame (missing: all of it, no truncation test);
    ``boxes``: :func:`visible_boxes` of ``segmentation`` when the caller has it.
    """
    out = []
    min_pixels, min_box = filt.scaled(np.shape(segmentation)[1])
    in_frame_pixels = in_frame_pixels or {}
    for oid, (x1, y1, x2, y2, n) in sorted((visible_boxes(segmentation) if boxes is None else boxes).items()):
        if oid not in class_of:
            continue
        full = max(int(full_pixels.get(oid, n)), n)
        inside = min(max(int(in_frame_pixels.get(oid, full)), n), full)
        keep = label_kept(n, min(x2 - x1, y2 - y1), full, inside, filt, min_pixels, min_box)
        out.append(ObjectLabel(oid, int(class_of[oid]), x1, y1, x2, y2, n, full, keep, inside))
    return out


def label_kept(
    visible: float, short_side: float, full: float, inside: float, filt: LabelFilter, min_pixels: float, min_box: float
) -> bool:
    """The label rule on one object: ``visible`` pixels, its visible box's shorter side, its whole
    silhouette's area ``full`` and the part of it ``inside`` the frame (``min_pixels``, ``min_box``: the
    filter's thresholds at the image's scale, :meth:`LabelFilter.scaled`)."""
    full = max(full, visible, 1e-9)
    inside = min(max(inside, visible), full)
    return bool(
        visible >= min_pixels
        and visible / full >= filt.min_visible_fraction
        and inside / full >= filt.min_in_frame_fraction
        and short_side >= min_box
    )


def yolo_lines(labels: list[ObjectLabel], width: int, height: int) -> list[str]:
    """YOLO txt rows ``class cx cy w h`` (normalised) of the kept labels."""
    rows = []
    for lb in labels:
        if not lb.keep:
            continue
        cx, cy = (lb.x1 + lb.x2) / 2.0 / width, (lb.y1 + lb.y2) / 2.0 / height
        rows.append(f"{lb.class_id} {cx:.6f} {cy:.6f} {lb.width / width:.6f} {lb.height / height:.6f}")
    return rows


def object_boxes(objects, margin_m: float = 0.05) -> NDArray[np.float64]:
    """``(N, 8, 3)`` world-frame corners of a box around each object (``WorldObject``: its convex footprint's
    axis-aligned bounds and its height range, grown by ``margin_m`` on every side, so a renderer's own
    tessellation of cylinders and spheres stays inside)."""
    out = np.empty((len(objects), 8, 3))
    for i, o in enumerate(objects):
        fp = np.asarray(o.footprint(), dtype=np.float64)
        z0, z1 = o.z_range()
        lo = np.array([*fp.min(axis=0), min(z0, 0.0)]) - margin_m
        hi = np.array([*fp.max(axis=0), z1]) + margin_m
        out[i] = box_corners(lo, hi)
    return out


def box_corners(lo: NDArray[np.float64], hi: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(8, 3)`` corners of the axis-aligned box ``lo``–``hi``."""
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])], dtype=np.float64)


def may_be_labelled(
    boxes: NDArray[np.float64],
    T_world_camera: NDArray[np.float64],
    K: NDArray[np.float64],
    width: int,
    height: int,
    near: float,
    min_pixels: float,
    min_box_px: float,
) -> bool:
    """False only when no object can become a kept label in this view, whatever hides it: every box of
    ``boxes`` (``(N, 8, 3)`` world frame, :func:`object_boxes`) projects, clipped to the image, to less
    than ``min_pixels`` or to a side shorter than ``min_box_px`` (a label's visible pixels and box lie inside
    that projection), or lies behind the camera. A box that crosses the camera's plane counts as visible.

    ``T_world_camera`` ``(4, 4)``: the optical frame (z forward, x right, y down); ``K``: its pinhole
    matrix. A cheap test before rendering: views that surely hold no label need no render to be judged."""
    if len(boxes) == 0:
        return False
    T_cw = np.linalg.inv(np.asarray(T_world_camera, dtype=np.float64))
    p = np.asarray(boxes, dtype=np.float64) @ T_cw[:3, :3].T + T_cw[:3, 3]  # (N, 8, 3) optical frame
    z = p[..., 2]
    front = z > near
    if np.any(front.any(axis=1) & ~front.all(axis=1)):  # a box across the near plane: unbounded projection
        return True
    full = front.all(axis=1)
    if not full.any():
        return False
    q = p[full]
    u = K[0, 0] * q[..., 0] / q[..., 2] + K[0, 2]
    v = K[1, 1] * q[..., 1] / q[..., 2] + K[1, 2]
    pad = 1.0  # a rasteriser's pixel on either side
    w = np.minimum(u.max(axis=1) + pad, width) - np.maximum(u.min(axis=1) - pad, 0.0)
    h = np.minimum(v.max(axis=1) + pad, height) - np.maximum(v.min(axis=1) - pad, 0.0)
    return bool(np.any((w >= min_box_px) & (h >= min_box_px) & (w * h >= min_pixels)))
