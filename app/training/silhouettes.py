"""Unoccluded, untruncated silhouette areas of a world's objects, rendered with pybullet's TinyRenderer.

The label rule (:mod:`app.training.labels`) compares an object's visible pixels with its *whole* silhouette
at the same pixel scale. :class:`SilhouetteRenderer` renders each object *alone* (its model the only one
drawn in a pybullet client of object models built from the same catalogue parts as the simulator,
:class:`ModelClient`) through an off-centre projection (:func:`frustum_matrix`) that covers exactly the
window of its projected bounding box on the camera's image plane extended past the frame
(:func:`silhouette_window`: left, right and bottom; not above the top edge, which cuts every tall object
seen from the robot's low camera). Occlusion by anything and truncation by the side and bottom edges both
lower the fraction, with the same rasteriser on both sides of the ratio, so a fully visible object scores
1.0. :func:`label_silhouettes` measures each object cheaply first (drawn from its model's convex parts,
:mod:`app.training.part_hulls`, or rendered coarsely) and renders it finely only where that measure's error
could change its label.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray

from app.training.labels import LabelFilter, box_corners, label_kept
from app.training.part_hulls import model_hulls, raster_silhouette

__all__ = ["silhouette_window", "frustum_matrix", "ModelClient", "SilhouetteRenderer", "label_silhouettes"]


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


def _grid(w: int, h: int, max_pixels: int) -> tuple[int, int]:
    """The render grid ``(rw, rh)`` of a ``w × h``-pixel window drawn on at most about ``max_pixels``."""
    s = max(1.0, math.sqrt(w * h / max_pixels))
    return max(1, int(math.ceil(w / s))), max(1, int(math.ceil(h / s)))


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

    def corners(self, model: str, scale: float) -> NDArray[np.float64]:
        """AABB corners ``[8, 4]`` (homogeneous, object frame) of ``model`` at ``scale``, built in the client
        if it is new; what the client draws does not change."""
        key = (str(model), float(scale))
        if key not in self._models:
            self._build(key)
        return self._models[key][1]

    def get(self, model: str, scale: float) -> tuple[int, NDArray[np.float64]]:
        """``(client, AABB corners [8, 4] homogeneous, object frame)`` of ``model`` at ``scale``, the only
        model drawn in the client until the next call."""
        key = (str(model), float(scale))
        if key not in self._models:
            self._build(key)
        if self._shown != key:
            self._show(self._shown, 0.0)
            self._show(key, 1.0)
            self._shown = key
        return self._cid, self._models[key][1]

    def _build(self, key: tuple[str, float]) -> None:
        import pybullet as p

        from app.world.models.bodies import build_model_pybullet

        if self._cid < 0:
            self._cid = p.connect(p.DIRECT)
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
        return {k: v[:2] for k, v in self.measure(
            T_world_camera, K, width, height, object_ids, margin=margin, margin_top=margin_top, max_pixels=max_pixels
        ).items()}

    def measure(
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
        raster_pixels: int | None = None,
    ) -> dict[int, tuple[int, int, int, int]]:
        """:meth:`silhouettes` with an error bound on each area: ``{object id: (area, area inside the frame,
        ± area error, ± inside error)}``, all in image pixels. A window rendered at the image's own scale has
        no error (the reference); one rendered coarser (scaled by ``s`` in each direction) can be off by the
        render pixels its outline crosses: those on either side of the outline (a pixel counts whole or not
        at all by its centre), and for the inside area also the silhouette's pixels that straddle a frame
        edge. (A feature thinner than a render pixel can fall between the pixel centres unseen: callers
        that must be sure render finely, see :func:`label_silhouettes`.)

        ``raster_pixels``: objects whose model is made of convex parts are not rendered but drawn from the
        parts' hulls (:func:`app.training.part_hulls.raster_silhouette`) on at most that many pixels, with
        the same bound (a fill and a render differ by the pixels the outline crosses); the others, and any
        object that reaches behind the near plane, are rendered at ``max_pixels``."""
        import pybullet as p

        T_wc = np.asarray(T_world_camera, dtype=np.float64)
        max_pixels = int(max_pixels or 16384)
        out: dict[int, tuple[int, int, int, int]] = {}
        for oid in object_ids:
            oid = int(oid)
            if not 0 <= oid < len(self.world.objects):
                continue
            o = self.world.objects[oid]
            corners = self._clients.corners(o.model, o.scale)
            c, s_ = math.cos(o.yaw), math.sin(o.yaw)
            T_wo = np.array([[c, -s_, 0.0, o.x], [s_, c, 0.0, o.y], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
            T = np.linalg.solve(T_wo, T_wc)  # the camera in the object's frame
            T_cam_obj = np.linalg.inv(T)
            eye = T[:3, 3]
            win = silhouette_window((T_cam_obj @ corners.T).T[:, :3], K, width, height, self.near, margin, margin_top)
            if win is None:
                out[oid] = (0, 0, 0, 0)
                continue
            u0, v0, u1, v1 = win
            w, h = u1 - u0, v1 - v0
            mask = None
            if raster_pixels and (hulls := model_hulls(o.model, o.scale)) is not None:
                rw, rh = _grid(w, h, int(raster_pixels))
                mask = raster_silhouette(hulls, T_cam_obj, K, win, rw, rh, self.near)
            if mask is None:
                rw, rh = _grid(w, h, max_pixels)
                cid, _ = self._clients.get(o.model, o.scale)
                view = p.computeViewMatrix(eye.tolist(), (eye + T[:3, 2]).tolist(), (-T[:3, 1]).tolist(), physicsClientId=cid)
                seg = p.getCameraImage(
                    rw, rh, view, frustum_matrix(K, win, self.near, self.far), renderer=p.ER_TINY_RENDERER,
                    physicsClientId=cid,
                )[4]
                mask = np.asarray(seg).reshape(rh, rw) >= 0
                exact = rw * rh == w * h
            else:
                exact = False
            # render pixel centres on the image plane: which of them fall inside the frame
            uc = u0 + (np.arange(rw) + 0.5) * (w / rw)
            vc = v0 + (np.arange(rh) + 0.5) * (h / rh)
            rows, cols = (vc >= 0) & (vc < height), (uc >= 0) & (uc < width)
            k = (w * h) / (rw * rh)
            full, inside = np.count_nonzero(mask) * k, np.count_nonzero(mask[np.ix_(rows, cols)]) * k
            if exact:
                out[oid] = (int(round(full)), int(round(inside)), 0, 0)
                continue
            # render pixels the outline crosses: silhouette pixels beside background and background beside
            # the silhouette (4-neighbours; the window's own edges are exact cuts)
            m = np.pad(mask, 1, mode="edge")
            core = m[1:-1, 1:-1]
            near_bg = ~(m[:-2, 1:-1] & m[2:, 1:-1] & m[1:-1, :-2] & m[1:-1, 2:])
            near_fg = m[:-2, 1:-1] | m[2:, 1:-1] | m[1:-1, :-2] | m[1:-1, 2:]
            err = (np.count_nonzero(core & near_bg) + np.count_nonzero(~core & near_fg)) * k
            # render pixels that straddle a frame edge (their centre decides inside or out)
            hw, hh = 0.5 * w / rw, 0.5 * h / rh
            straddle_c = (np.abs(uc) < hw) | (np.abs(uc - width) < hw)
            straddle_r = np.abs(vc - height) < hh
            edge = np.count_nonzero(mask[:, straddle_c]) + np.count_nonzero(mask[straddle_r, :])
            out[oid] = (int(round(full)), int(round(inside)), int(math.ceil(err)), int(math.ceil(err + edge * k)))
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


def label_silhouettes(
    renderer: SilhouetteRenderer,
    T_world_camera: NDArray[np.float64],
    K: NDArray[np.float64],
    width: int,
    height: int,
    boxes: Mapping[int, tuple[int, int, int, int, int]],
    filt: LabelFilter,
    *,
    coarse_pixels: int = 2048,
    max_pixels: int = 16384,
    raster: bool = True,
) -> dict[int, tuple[int, int]]:
    """``{object id: (area, area inside the frame)}`` of the objects in ``boxes`` (their visible boxes and
    pixel counts, :func:`~app.training.labels.visible_boxes`) for the label rule ``filt``, at the cost of
    coarse measures where the answer is clear.

    Each object is measured first: drawn from its convex parts' hulls on at most ``max_pixels`` (``raster``,
    where its model allows) or rendered with at most ``coarse_pixels``; when its label decision could change
    anywhere within those areas' error bounds (:meth:`SilhouetteRenderer.measure`), it is rendered again
    with at most ``max_pixels`` (what :meth:`SilhouetteRenderer.silhouettes` gives), and that count is used.
    An object whose other tests already fail (too few pixels, too narrow a box) keeps its first areas.
    The label decisions are those of the fine renders; the recorded areas of the others are within their
    bounds (a few per cent)."""
    min_pixels, min_box = filt.scaled(width)
    coarse = renderer.measure(
        T_world_camera, K, width, height, list(boxes), max_pixels=min(coarse_pixels, max_pixels),
        raster_pixels=max_pixels if raster else None,
    )
    redo = []
    for oid, (full, inside, e_full, e_inside) in coarse.items():
        x1, y1, x2, y2, n = boxes[oid]
        side = min(x2 - x1, y2 - y1)
        if not (e_full or e_inside) or n < min_pixels or side < min_box:
            continue
        decisions = {
            label_kept(n, side, f, i, filt, min_pixels, min_box)
            for f in (max(full - e_full, 1), full + e_full)
            for i in (max(inside - e_inside, 0), inside + e_inside)
        }
        if len(decisions) > 1:
            redo.append(oid)
    out = {k: v[:2] for k, v in coarse.items()}
    if redo:
        out.update(renderer.silhouettes(T_world_camera, K, width, height, redo, max_pixels=max_pixels))
    return out
