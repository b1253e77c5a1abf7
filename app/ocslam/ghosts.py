"""Ghost decay (improved mode): objects in clear view that no box explains lose presence.

A frame is a *clear miss* for an object when its centre projects inside the image, at least
``clear_view_in_frame`` of its outline's image box is inside the image (the detector's labelling rule), that
part's smaller side is at least ``clear_view_min_px`` (the detector rarely boxes an object that looks smaller),
it lies within ``decay_max_range_m``, no box of its class covers its bearing, no box of a nearer object covers its
image columns and top, nor do such boxes together cover more than ``hidden_covered_share`` of its columns
(:func:`hidden_behind`), and the LIDAR does not see something in front of it. An object decays
only once its clear misses outnumber its detections.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from app.ocslam.camera import CameraModel
from app.ocslam.candidate import FrameReport
from app.ocslam.config import ConsciousnessConfig
from app.ocslam.presence import (
    centers_in_camera_view,
    decay_presence,
    in_frame_boxes,
    occluded_by_scan,
    visible_share,
)
from app.ocslam.projection import BoundingArea
from app.ocslam.se2 import Pose2
from app.ocslam.tracks import Track

FloatArray = NDArray[np.float64]

#: the width of the image the detector sees (its static input, whatever the camera's resolution):
#: ``clear_view_min_px`` is measured there
DETECTOR_INPUT_WIDTH_PX = 320.0


def own_near_range(t: Track, T_map_scan: Pose2) -> float | None:
    """The nearest of ``t``'s own LIDAR points from the scan's origin (m), or None without points. A return in
    front of them by more than the occlusion margin is another surface's, even where the footprint (completed
    to the class's shape) reaches nearer: an object seen from one side of a partition and completed into it is
    hidden from the other side by the partition's face, which lies on no point of the object."""
    if not t.evidence.has_points:
        return None
    d = t.evidence.points - np.array([T_map_scan.x, T_map_scan.y])
    return float(np.sqrt(np.min(np.einsum("ij,ij->i", d, d))))


def in_clear_view(
    tracks: Sequence[Track],
    centers: FloatArray,
    heights_m: FloatArray,
    T_base_map: Pose2,
    cam: CameraModel,
    max_range_m: float,
    frame_share: float,
    min_side_px: float,
) -> tuple[NDArray[np.bool_], FloatArray]:
    """Which of ``tracks`` (with footprints; their ``(N, 2)`` map ``centers`` and ``(N,)`` heights) the detector
    would be asked to box from ``T_base_map``'s inverse pose: ``(in_view (N,), side_px (N,))``. In view: the centre
    projects inside the image within ``max_range_m``, at least ``frame_share`` of the outline's image box is inside
    the image (the detector's labels leave out objects less than half in the frame) and that part's smaller side,
    ``side_px`` in the detector's input, is at least ``min_side_px`` (it rarely boxes an object that looks smaller);
    ``side_px`` is 0 where the centre is not in view or neither of the last two tests is asked for."""
    in_view = centers_in_camera_view(centers, heights_m, T_base_map, cam, max_range_m)
    side_px = np.zeros(len(in_view))
    if (frame_share > 0.0 or min_side_px > 0.0) and in_view.any():
        idx = np.flatnonzero(in_view)
        corners = np.stack([tracks[k].footprint.corners for k in idx.tolist()])
        frac, side = in_frame_boxes(corners, heights_m[idx], T_base_map, cam)
        side *= DETECTOR_INPUT_WIDTH_PX / float(cam.info.width)  # as the detector's input sees it
        side_px[idx] = side
        in_view[idx] = (frac >= frame_share) & (side >= min_side_px)
    return in_view, side_px


def hidden_behind(
    corners: FloatArray, heights_m: FloatArray, areas: Sequence[BoundingArea], T_base_map: Pose2, cam: CameraModel, margin_m: float,
    covered_share: float = 1.0,
) -> NDArray[np.bool_]:
    """``(N,)`` True where one box of the frame hides an object from the camera: the box covers the image columns of
    all of the object's footprint ``corners`` ``(N, 4, 2)`` (map) and reaches above its top (``heights_m`` ``(N,)``),
    and the box's object stands more than ``margin_m`` nearer than the object's nearest corner (its bottom edge's
    range; a box cut by the image's bottom: nearer still). A chair's legs let the LIDAR see an object behind it,
    its seat and back do not let the camera. With ``covered_share`` < 1, the boxes that stand nearer and reach above
    its top also hide it together when their columns cover more than that share of its own (a table half behind a
    chair's box: the detector seldom boxes an object mostly hidden)."""
    n = len(corners)
    hid = np.zeros(n, dtype=bool)
    if not n or not areas:
        return hid
    c_base = T_base_map.transform_points(corners.reshape(-1, 2))
    p = np.empty((len(c_base), 3))
    p[:, :2] = c_base
    p[:, 2] = np.repeat(heights_m, corners.shape[1])
    uv, depth = cam.project(p)
    ok = (depth > 0.05).reshape(n, -1).all(axis=1)  # every corner in front of the camera
    u = uv[:, 0].reshape(n, -1)
    v_top = uv[:, 1].reshape(n, -1).min(axis=1)  # the highest image row of the object's top outline
    r = np.hypot(c_base[:, 0] - cam.center_base[0], c_base[:, 1] - cam.center_base[1]).reshape(n, -1).min(axis=1)
    with np.errstate(invalid="ignore"):
        u_lo, u_hi = u.min(axis=1), u.max(axis=1)
        cover = []  # per box: its columns and the objects it stands in front of, above their tops
        for a in areas:
            x1, y1, x2, _y2 = a.box_px.tolist()
            near = a.near_range_m if a.bottom_reliable else 0.0
            front = ok & (v_top >= y1) & (near < r - margin_m)
            hid |= front & (x1 <= u_lo) & (u_hi <= x2)
            cover.append((x1, x2, front))
    if covered_share < 1.0:
        for k in np.flatnonzero(ok & ~hid).tolist():
            lo_k, hi_k = float(u_lo[k]), float(u_hi[k])
            spans = sorted((max(x1, lo_k), min(x2, hi_k)) for x1, x2, front in cover if front[k] and x2 > lo_k and x1 < hi_k)
            covered, reach = 0.0, lo_k
            for a0, a1 in spans:  # the union's length
                if a1 > reach:
                    covered += a1 - max(a0, reach)
                    reach = a1
            hid[k] = covered > covered_share * max(hi_k - lo_k, 1e-9)
    return hid


def decay_tracks(
    tracks: list[Track],
    areas: Sequence[BoundingArea],
    T_map_base: Pose2,
    T_map_scan: Pose2,
    beam_b_scan: FloatArray,
    beam_r_scan: FloatArray,
    stamp: float,
    dt: float,
    rep: FrameReport,
    cfg: ConsciousnessConfig,
    cam: CameraModel,
) -> list[Track]:
    """Ghost decay; returns the tracks that remain (presence > 0).

    The per-track tests that need no scan run for every track at once: in the camera's view, then
    explained by a box's wedge for those in view; the occlusion test only for the tracks still missed."""
    T_scan_map = T_map_scan.inverse()
    T_base_map = T_map_base.inverse()
    labels = {a.label for a in areas}
    cand = [t for t in tracks if t.footprint is not None and t.touched_stamp != stamp]
    missed: set[int] = set()  # ids of the tracks in clear view that no box explains
    if cand:
        centers = np.array([t.footprint.center for t in cand if t.footprint is not None], dtype=np.float64).reshape(-1, 2)
        heights = np.array([t.prior.height[1] for t in cand], dtype=np.float64)
        in_view, _side = in_clear_view(
            cand, centers, heights, T_base_map, cam, float(cfg.decay_max_range_m), float(cfg.clear_view_in_frame),
            float(cfg.clear_view_min_px),
        )
        view = np.flatnonzero(in_view).tolist()
        # of those, the ones explained by a box of their class whose wedge holds them
        boxed = [k for k in view if cand[k].label in labels]
        explained: set[int] = set()
        if boxed:
            b, _r = cam.bearing_ranges_scan(T_scan_map.transform_points(centers[boxed]))
            held = np.zeros(len(b), dtype=bool)
            boxed_labels = np.array([cand[k].label for k in boxed], dtype=object)
            # a box explains one object: one that gave an object of this frame explains no other, but for the
            # objects seen apart from that one before (two boxes, two islands): the detector boxed the two as one
            taken: dict[int, int] = {}
            if cfg.box_explains_one:
                for t in tracks:
                    if t.touched_stamp == stamp and stamp in t.boxes:
                        taken[t.boxes[stamp]] = t.id
            for j, a in enumerate(areas):
                rows = boxed_labels == a.label
                if j in taken:
                    owner = taken[j]
                    rows &= np.array([owner in cand[k].apart for k in boxed], dtype=bool)
                if rows.any():
                    held[rows] |= a.contains_bearing(b[rows], margin=0.05)
            explained = {boxed[r] for r in np.flatnonzero(held).tolist()}
        unexplained = [k for k in view if k not in explained]
        if cfg.hidden_behind_boxes and unexplained:
            corners = np.stack([cand[k].footprint.corners for k in unexplained])
            hid = hidden_behind(corners, heights[unexplained], areas, T_base_map, cam, float(cfg.occlusion_margin_m),
                                float(cfg.hidden_covered_share))
            unexplained = [k for k, h in zip(unexplained, hid.tolist()) if not h]
        missed = {id(cand[k]) for k in unexplained}
    if not missed:
        return list(tracks)
    keep = []
    share, margin = float(cfg.clear_view_visible), float(cfg.occlusion_margin_m)
    for t in tracks:
        if id(t) not in missed:
            keep.append(t)
            continue
        fp = t.footprint
        assert fp is not None
        near = own_near_range(t, T_map_scan) if cfg.clear_view_own_points else None
        if occluded_by_scan(fp, T_map_scan, beam_b_scan, beam_r_scan, margin, near) or (
            share > 0.0 and visible_share(fp, T_map_scan, beam_b_scan, beam_r_scan, margin, t.prior.length[1], near) < share
        ):
            keep.append(t)
            continue
        # a clear miss. Detectors miss real objects now and then (and the camera may be blocked above
        # the LIDAR's plane), so only an object missed more often than it was detected decays.
        t.missed(stamp)
        if t.misses <= t.detections:
            keep.append(t)
            continue
        t.presence = decay_presence(t.presence, float(cfg.decay_rate_per_s), dt)
        rep.decayed += 1
        if t.presence > 0.0:
            keep.append(t)
        else:
            rep.removed += 1
    return keep
