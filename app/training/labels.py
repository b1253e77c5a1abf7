"""Detector labels from the simulator's segmentation mask.

A label is the tight box of an object's *visible* pixels (so truncated and partly occluded objects get
the box a detector must predict). It is kept when enough of the object is visible:

- ``visible_pixels ≥ min_pixels`` (the object covers enough of the image), and
- ``visible_fraction ≥ min_visible_fraction``, where ``visible_fraction = visible_pixels / full_pixels``
  and ``full_pixels`` is the object's *unoccluded, untruncated* silhouette area at the same pixel scale
  (rendered alone on an image plane that extends past the frame, see :func:`silhouette_window`), and
- ``in_frame_fraction ≥ min_in_frame_fraction``: at least half of the silhouette is inside the frame
  (an object cut by the sides or the bottom to less than half of itself, like one table leg or a sofa
  filling the view from 20 cm, has lost what tells it apart), and
- the box's shorter side ≥ ``min_box_px``.

Objects that are visible but fail these tests are returned as *ignore* regions: they are not training
labels (a sliver of a table leg is no "table"), and the benchmark does not count a detection on them as
a false positive (COCO ``iscrowd``).

``full_pixels`` comes from :class:`SilhouetteRenderer`: each object is rendered *alone* (its model the only
one drawn in a pybullet client of object models built from the same catalogue parts as the simulator) through an off-centre
projection (:func:`frustum_matrix`) that covers exactly the window of its projected bounding box on the
camera's image plane extended past the frame (left, right and bottom; not above the top edge, which
cuts every tall object seen from the robot's low camera), at the same pixel scale. Occlusion by
anything and truncation by the side and bottom edges both lower the fraction, with the same rasteriser
on both sides of the ratio, so a fully visible object scores 1.0. The rest of this module is numpy only.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "LabelFilter",
    "ObjectLabel",
    "visible_boxes",
    "make_labels",
    "yolo_lines",
    "silhouette_window",
    "frustum_matrix",
    "SilhouetteRenderer",
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
        keep = (
            n >= min_pixels
            and n / full >= filt.min_visible_fraction
            and inside / full >= filt.min_in_frame_fraction
            and min(x2 - x1, y2 - y1) >= min_box
        )
        out.append(ObjectLabel(oid, int(class_of[oid]), x1, y1, x2, y2, n, full, bool(keep), inside))
    return out


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


def silhouette_window(
    points_cam: NDArray[np.float64],
    K: NDArray[np.float64],
    width: int,
    height: int,
    near: float,
    margin: float = 1.0,
    margin_top: float | None = None,
) -> tuple[int, int, int, int] | None:
    """The pixel window ``(u0, v0, u1, v1)`` (exclusive ends) that holds an object's whole silhouette on
    the camera's image plane *extended past the frame* by ``margin`` frame sizes to the left, right and
    bottom and ``margin_top`` (default: ``margin``) above the top edge.

    ``points_cam`` are ``(N, 3)`` points bounding the object (e.g. its AABB corners) in the optical frame
    (z forward, x right, y down). Points behind the near plane make the projection unbounded on that
    side; the window is then the extended plane's edge. ``None`` if the object is entirely behind the
    camera or the window misses the extended plane.
    """
    p = np.asarray(points_cam, dtype=np.float64)
    lo_u, hi_u = -margin * width, (1 + margin) * width
    lo_v, hi_v = -(margin if margin_top is None else margin_top) * height, (1 + margin) * height
    front = p[:, 2] > near
    if not np.any(front):
        return None
    if np.all(front):
        u = K[0, 0] * p[:, 0] / p[:, 2] + K[0, 2]
        v = K[1, 1] * p[:, 1] / p[:, 2] + K[1, 2]
        u0, u1, v0, v1 = u.min(), u.max(), v.min(), v.max()
    else:  # straddles the camera plane: unbounded; fall back to the whole extended plane
        u0, u1, v0, v1 = lo_u, hi_u, lo_v, hi_v
    u0, v0 = max(math.floor(u0), lo_u), max(math.floor(v0), lo_v)
    u1, v1 = min(math.ceil(u1) + 1, hi_u), min(math.ceil(v1) + 1, hi_v)
    if u1 <= u0 or v1 <= v0:
        return None
    return int(u0), int(v0), int(u1), int(v1)


def frustum_matrix(
    K: NDArray[np.float64], window: tuple[int, int, int, int], near: float, far: float
) -> list[float]:
    """OpenGL projection (column-major, 16 floats, for pybullet's ``getCameraImage``) that renders exactly
    the pixel window ``(u0, v0, u1, v1)`` of the pinhole camera ``K`` at one pixel per image pixel.

    Pixel ``u`` maps to the view-space ray ``x/z = (u - cx)/fx``; the window's edges become glFrustum's
    ``left/right/bottom/top`` on the near plane (y up in OpenGL, so image rows flip).
    """
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    u0, v0, u1, v1 = window
    left = (u0 - cx) / fx * near
    right = (u1 - cx) / fx * near
    top = -(v0 - cy) / fy * near
    bottom = -(v1 - cy) / fy * near
    m = np.zeros((4, 4))
    m[0, 0] = 2 * near / (right - left)
    m[1, 1] = 2 * near / (top - bottom)
    m[0, 2] = (right + left) / (right - left)
    m[1, 2] = (top + bottom) / (top - bottom)
    m[2, 2] = -(far + near) / (far - near)
    m[2, 3] = -2 * far * near / (far - near)
    m[3, 2] = -1.0
    return m.T.ravel().tolist()  # column-major


class ModelClient:
    """The object models (per scale) in one pybullet DIRECT client, each alone at the origin, geometry from
    ``app.world.models.bodies.build_model_pybullet`` exactly as the simulator builds it. :meth:`get` shows
    the model asked for and hides the others (fully transparent: TinyRenderer skips them, in the image,
    the segmentation and the time a render takes), so any world's objects of that model are rendered with
    the camera moved into the object's frame. The client outlives a world (a dataset worker keeps one for
    all its worlds); one client, not one a model: each costs ~30 MB and up to a quarter second to open.
    Close it to free it."""

    def __init__(self) -> None:
        self._cid = -1
        #: (model, scale) → (its bodies that have a visual shape, AABB corners [8, 4] homogeneous, object frame)
        self._models: dict[tuple[str, float], tuple[list[int], NDArray[np.float64]]] = {}
        self._shown: tuple[str, float] | None = None

    def __len__(self) -> int:
        """How many models (and scales) the client holds."""
        return len(self._models)

    def _show(self, key: tuple[str, float] | None, alpha: float) -> None:
        import pybullet as p

        for b in self._models[key][0] if key is not None else ():
            p.changeVisualShape(b, -1, rgbaColor=[1.0, 1.0, 1.0, alpha], physicsClientId=self._cid)

    def get(self, model: str, scale: float) -> tuple[int, NDArray[np.float64]]:
        """``(client, AABB corners [8, 4] homogeneous, object frame)`` of ``model`` at ``scale``, the only
        model drawn in the client until the next call."""
        import pybullet as p

        key = (str(model), float(scale))
        if self._cid < 0:
            self._cid = p.connect(p.DIRECT)
        if key not in self._models:
            from app.world.models.bodies import build_model_pybullet

            cid = self._cid
            bodies = [b for b, _ in build_model_pybullet(cid, key[0], 0.0, 0.0, 0.0, scale=key[1])]
            lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
            for b in bodies:
                a0, a1 = p.getAABB(b, -1, physicsClientId=cid)
                lo, hi = np.minimum(lo, a0), np.maximum(hi, a1)
            corners = np.c_[box_corners(lo, hi), np.ones(8)]
            visual = [b for b in bodies if p.getVisualShapeData(b, physicsClientId=cid)]
            self._models[key] = (visual, corners)
            self._show(key, 0.0)
        if self._shown != key:
            self._show(self._shown, 0.0)
            self._show(key, 1.0)
            self._shown = key
        return self._cid, self._models[key][1]

    def close(self) -> None:
        import pybullet as p

        if self._cid >= 0:
            try:
                p.disconnect(self._cid)
            except Exception:
                pass
        self._cid, self._shown = -1, None
        self._models.clear()


class SilhouetteRenderer:
    """Unoccluded, untruncated pixel areas of a world's objects, for any camera pose.

    Each object is rendered alone, its model the only one drawn in the models' client (:class:`ModelClient`:
    the model at the origin; the camera is moved into the object's frame), so a render costs only that object's triangles and the
    window's pixels. ``clients``: a set shared with other worlds (left open by :meth:`close`); by default
    the renderer makes its own. Close it (or use it as a context manager) to free its clients.
    """

    def __init__(self, world, near: float = 0.05, far: float = 20.0, clients: ModelClient | None = None) -> None:
        self.world = world
        self.near, self.far = float(near), float(far)
        self._own = clients is None
        self._clients = ModelClient() if clients is None else clients

    def counts(
        self,
        T_world_camera: NDArray[np.float64],
        K: NDArray[np.float64],
        width: int,
        height: int,
        object_ids,
        *,
        margin: float = 1.0,
        margin_top: float = 0.0,
        max_pixels: int | None = None,
    ) -> dict[int, int]:
        """``{object id: pixel area}`` (see :meth:`silhouettes`)."""
        return {k: v[0] for k, v in self.silhouettes(
            T_world_camera, K, width, height, object_ids, margin=margin, margin_top=margin_top, max_pixels=max_pixels
        ).items()}

    def silhouettes(
        self,
        T_world_camera: NDArray[np.float64],
        K: NDArray[np.float64],
        width: int,
        height: int,
        object_ids,
        *,
        margin: float = 1.0,
        margin_top: float = 0.0,
        max_pixels: int | None = None,
    ) -> dict[int, tuple[int, int]]:
        """``{object id: (pixel area, pixel area inside the frame)}`` of each object alone in the camera ``K`` at ``T_world_camera``
        (optical frame, z forward), on the image plane extended ``margin`` frame sizes past the left,
        right and bottom edges and ``margin_top`` above the top edge.

        ``margin_top = 0`` (the default) does not count what lies above the frame: the robot's low,
        level camera cuts every tall object (doors, shelves, people) at the top edge, which is how it
        always sees them, and they stay recognisable from their lower part; objects cut at the sides
        or the bottom lose the parts that tell them apart (a table leg is no table).
        Windows larger than ``max_pixels`` (default 16384: counts to about 1 %) are rendered coarser and
        scaled back."""
        import pybullet as p

        T_wc = np.asarray(T_world_camera, dtype=np.float64)
        max_pixels = int(max_pixels or 16384)
        out: dict[int, tuple[int, int]] = {}
        for oid in object_ids:
            oid = int(oid)
            if not 0 <= oid < len(self.world.objects):
                continue
            o = self.world.objects[oid]
            cid, corners = self._clients.get(o.model, o.scale)
            c, s_ = math.cos(o.yaw), math.sin(o.yaw)
            T_wo = np.array([[c, -s_, 0.0, o.x], [s_, c, 0.0, o.y], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
            T = np.linalg.solve(T_wo, T_wc)  # the camera in the object's frame
            T_cam_world = np.linalg.inv(T)
            eye = T[:3, 3]
            win = silhouette_window((T_cam_world @ corners.T).T[:, :3], K, width, height, self.near, margin, margin_top)
            if win is None:
                out[oid] = (0, 0)
                continue
            u0, v0, u1, v1 = win
            w, h = u1 - u0, v1 - v0
            s = max(1.0, math.sqrt(w * h / max_pixels))
            rw, rh = max(1, int(math.ceil(w / s))), max(1, int(math.ceil(h / s)))
            view = p.computeViewMatrix(eye.tolist(), (eye + T[:3, 2]).tolist(), (-T[:3, 1]).tolist(), physicsClientId=cid)
            seg = p.getCameraImage(
                rw, rh, view, frustum_matrix(K, win, self.near, self.far), renderer=p.ER_TINY_RENDERER, physicsClientId=cid
            )[4]
            mask = np.asarray(seg).reshape(rh, rw) >= 0
            # render pixel centres on the image plane: which of them fall inside the frame
            uc = u0 + (np.arange(rw) + 0.5) * (w / rw)
            vc = v0 + (np.arange(rh) + 0.5) * (h / rh)
            inside = mask[np.ix_((vc >= 0) & (vc < height), (uc >= 0) & (uc < width))]
            k = (w * h) / (rw * rh)
            out[oid] = (int(round(np.count_nonzero(mask) * k)), int(round(np.count_nonzero(inside) * k)))
        return out

    def close(self) -> None:
        if self._own:
            self._clients.close()

    def __enter__(self) -> SilhouetteRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self) -> None:  # pragma: no cover - best effort
        try:
            self.close()
        except Exception:
            pass
