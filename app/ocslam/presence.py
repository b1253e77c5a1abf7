"""Soft decision (paper §2.5.4) and ghost decay.

Presence confidence: ``X_p0 = c/F``; on each new frame in which the object is seen again,
``X_f ← min(X_f + 1, F)`` then ``X_p ← max(X_p, Y_c·X_f/F)`` (the implementation's order and cap;
the paper's text increments after and without a cap, which would let ``X_p`` exceed 1).

Presence evidence (improved mode): the published presence is the soft decision's capped by
:func:`evidence_presence`, the probability that the object is there given the frames that boxed it and
the frames in which it was in clear view but not boxed.

Ghost decay (improved mode): an object whose position is in the camera's view, within range and not
occluded according to the LIDAR, but that no box of its class explains, loses
``decay_rate_per_s · dt`` of presence. Occluded objects keep theirs.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from app.ocslam.camera import CameraModel
from app.ocslam.footprint import Footprint
from app.ocslam.se2 import Pose2

FloatArray = NDArray[np.float64]


def initial_presence(confidence: float, frames_for_presence: int) -> float:
    """``X_p0 = c / F``."""
    return float(np.clip(confidence, 0.0, 1.0)) / max(int(frames_for_presence), 1)


def update_presence(presence: float, frames: int, confidence: float, frames_for_presence: int) -> tuple[float, int]:
    """One new frame: ``f ← min(f + 1, F)``, ``p ← max(p, c·f/F)``. Returns ``(p, f)``."""
    F = max(int(frames_for_presence), 1)
    f = min(int(frames) + 1, F)
    p = max(float(presence), float(np.clip(confidence, 0.0, 1.0)) * f / F)
    return p, f


def evidence_presence(detections: int, misses: int, detection_rate: float, false_detection_rate: float) -> float:
    """P(the object is there | boxed in ``detections`` frames, missed in ``misses`` frames of clear view).

    A binary Bayes filter from an even prior: a frame that boxes the object multiplies its odds by
    ``q1/q0``, a clear miss by ``(1 − q1)/(1 − q0)``, where ``q1 = detection_rate`` is how often the
    detector boxes an object that is there and in clear view, and ``q0 = false_detection_rate`` how often
    it boxes that class again at a place where it fired without an object (a stool taken for a gnome).
    1.0 (no evidence against) unless ``0 < q0 < q1 < 1``."""
    q1, q0 = float(detection_rate), float(false_detection_rate)
    if not 0.0 < q0 < q1 < 1.0:
        return 1.0
    log_odds = max(int(detections), 0) * math.log(q1 / q0) - max(int(misses), 0) * math.log((1.0 - q0) / (1.0 - q1))
    return 1.0 / (1.0 + math.exp(-min(max(log_odds, -50.0), 50.0)))


def decay_presence(presence: float, rate_per_s: float, dt: float) -> float:
    """Presence after ``dt`` seconds of being in view but not detected (never below 0)."""
    return max(0.0, float(presence) - max(rate_per_s, 0.0) * max(dt, 0.0))


def in_camera_view(
    footprint: Footprint,
    height_m: float,
    T_frame_base: Pose2,
    camera: CameraModel,
    max_range_m: float,
    margin_frac: float = 0.08,
    T_base_frame: Pose2 | None = None,
) -> bool:
    """True if the object's centre (at mid-height, capped at 1 m) projects inside the image's inner part
    and lies within ``max_range_m`` of the camera (horizontally). ``T_base_frame``: ``T_frame_base``'s
    inverse when the caller has it (one per frame, not one per object)."""
    T_bf = T_frame_base.inverse() if T_base_frame is None else T_base_frame
    return bool(centers_in_camera_view(footprint.center[None, :], np.array([height_m]), T_bf, camera,
                                       max_range_m, margin_frac)[0])


def centers_in_camera_view(
    centers: FloatArray,
    heights_m: FloatArray,
    T_base_frame: Pose2,
    camera: CameraModel,
    max_range_m: float,
    margin_frac: float = 0.08,
) -> NDArray[np.bool_]:
    """:func:`in_camera_view` for ``(N, 2)`` object centres in the frame with ``(N,)`` heights at once.

    ``T_base_frame``: the frame's pose in ``base_footprint`` (the inverse of ``T_frame_base``).
    Returns ``(N,)`` True where the centre is in view."""
    c_base = T_base_frame.transform_points(centers)
    p = np.empty((len(c_base), 3))
    p[:, :2] = c_base
    p[:, 2] = np.minimum(np.maximum(0.5 * np.asarray(heights_m, dtype=np.float64).reshape(-1), 0.02), 1.0)
    uv, depth = camera.project(p)
    W, H = camera.info.width, camera.info.height
    u, v = uv[:, 0], uv[:, 1]
    with np.errstate(invalid="ignore"):
        ok = depth > 0.05
        ok &= (margin_frac * W <= u) & (u <= (1.0 - margin_frac) * W)
        ok &= (0.0 <= v) & (v <= H)
    cx, cy = camera.center_base[:2].tolist()
    ok &= np.hypot(c_base[:, 0] - cx, c_base[:, 1] - cy) <= max_range_m
    return ok


def in_frame_boxes(
    corners: FloatArray, heights_m: FloatArray, T_base_frame: Pose2, camera: CameraModel
) -> tuple[FloatArray, FloatArray]:
    """Each object's image box and how much of it the image holds: ``(fraction, side_px)``, both ``(N,)``.

    The box is that of its 3D outline (its footprint's ``(N, 4, 2)`` corners in the frame, from the floor to
    ``(N,)`` heights) projected without clipping; ``fraction`` is the share of that box inside the image (the
    rule the detector's labels follow: an object less than half in the frame is not labelled, so not expected
    to be boxed), ``side_px`` the smaller side of its part inside the image, in pixels (how large the detector
    would see it). Both 0 for an outline reaching behind the camera (an object the camera is inside of, or
    beside)."""
    c = np.asarray(corners, dtype=np.float64).reshape(-1, 4, 2)
    n = len(c)
    if n == 0:
        return np.zeros(0), np.zeros(0)
    c_base = T_base_frame.transform_points(c.reshape(-1, 2)).reshape(n, 4, 2)
    p = np.empty((n, 8, 3))
    p[:, :4, :2] = c_base
    p[:, 4:, :2] = c_base
    p[:, :4, 2] = 0.0
    p[:, 4:, 2] = np.asarray(heights_m, dtype=np.float64).reshape(-1, 1)
    uv, depth = camera.project(p.reshape(-1, 3))
    uv, depth = uv.reshape(n, 8, 2), depth.reshape(n, 8)
    W, H = float(camera.info.width), float(camera.info.height)
    with np.errstate(invalid="ignore"):
        u0, u1 = uv[:, :, 0].min(axis=1), uv[:, :, 0].max(axis=1)
        v0, v1 = uv[:, :, 1].min(axis=1), uv[:, :, 1].max(axis=1)
        area = np.maximum(u1 - u0, 1e-9) * np.maximum(v1 - v0, 1e-9)
        w_in = np.clip(np.minimum(u1, W) - np.maximum(u0, 0.0), 0.0, None)
        h_in = np.clip(np.minimum(v1, H) - np.maximum(v0, 0.0), 0.0, None)
        frac = w_in * h_in / area
        side = np.minimum(w_in, h_in)
    bad = ~np.all(depth > 0.05, axis=1) | ~np.isfinite(frac) | ~np.isfinite(side)
    frac[bad] = 0.0
    side[bad] = 0.0
    return frac, side


def angular_span(footprint: Footprint, T_frame_scan: Pose2, near_m: float | None = None) -> tuple[float, float, float]:
    """The object as the scan's origin sees it: ``(mid, half, r)``, the bearing of the middle of its
    footprint's angular span, half that span (rad, about the scan origin) and its nearest distance (m;
    0 when the origin is inside it). ``near_m``: where the object may begin, if farther than its footprint's
    nearest point (its own LIDAR points' nearest range): ``r`` is the farther of the two (unless 0)."""
    T_scan_frame = T_frame_scan.inverse()
    corners = T_scan_frame.transform_points(np.vstack([footprint.corners, footprint.center[None, :]]))
    b = np.arctan2(corners[:, 1], corners[:, 0])
    rel = (b - b[-1] + np.pi) % (2 * np.pi) - np.pi
    lo, hi = b[-1] + rel.min(), b[-1] + rel.max()
    r_obj = float(footprint.transformed(T_scan_frame).nearest_distance(np.zeros(2)))
    if near_m is not None and r_obj > 0.0:
        r_obj = max(r_obj, float(near_m))
    return float(0.5 * (lo + hi)), float(0.5 * (hi - lo)), r_obj


def occluded_by_scan(
    footprint: Footprint,
    T_frame_scan: Pose2,
    beam_bearings: FloatArray,
    beam_ranges: FloatArray,
    margin_m: float,
    near_m: float | None = None,
) -> bool:
    """True if the LIDAR sees something at least ``margin_m`` in front of the object over most of it.

    ``beam_bearings``/``beam_ranges``: ``(N,)`` beams about the scan origin (``inf``: no return).
    ``near_m``: where the object may begin, if farther than its footprint's nearest point (:func:`angular_span`).
    """
    mid, half_span, r_obj = angular_span(footprint, T_frame_scan, near_m)
    # shrink to the central half so the object's own outline does not count
    half = 0.5 * half_span
    off = (beam_bearings - mid + np.pi) % (2 * np.pi) - np.pi
    sel = np.abs(off) <= max(half, 0.6 * np.deg2rad(1.0))
    if not np.any(sel):
        sel = np.zeros(len(off), dtype=bool)
        if len(off):
            sel[np.argmin(np.abs(off))] = True
    if not np.any(sel):
        return False
    if r_obj <= 0.0:
        return False
    blocked = beam_ranges[sel] < r_obj - margin_m
    return bool(np.mean(blocked) > 0.5)


def visible_share(
    footprint: Footprint,
    T_frame_scan: Pose2,
    beam_bearings: FloatArray,
    beam_ranges: FloatArray,
    margin_m: float,
    extent_m: float,
    near_m: float | None = None,
) -> float:
    """Share of the object the LIDAR sees, counting what may continue behind a nearer return at its edge.

    The footprint is only what the LIDAR has shown of the object so far: where a beam just beside its
    angular span returns at least ``margin_m`` in front of it (a wall stub, another object), the object
    may go on behind that return, up to ``extent_m`` (its class' typical length). Returns
    ``seen / (span + hidden run)``: the beams inside the span that reach the object, over the beams of the
    span plus the run of blocked beams adjoining it on either side (within ``extent_m`` at the object's
    range). 1.0 when no beam falls near the object; 0.0 when it is behind the scan's origin.
    ``near_m``: where the object may begin, if farther than its footprint's nearest point (:func:`angular_span`).

    ``beam_bearings``/``beam_ranges``: ``(N,)`` beams about the scan origin (``inf``: no return)."""
    b_all = np.asarray(beam_bearings, dtype=np.float64)
    r_all = np.asarray(beam_ranges, dtype=np.float64)
    if len(b_all) == 0:
        return 1.0
    mid, half, r_obj = angular_span(footprint, T_frame_scan, near_m)
    if r_obj <= 0.0:
        return 0.0
    off = (b_all - mid + np.pi) % (2 * np.pi) - np.pi
    blocked = r_all < r_obj - margin_m
    inside = np.abs(off) <= half
    if not inside.any():
        inside[np.argmin(np.abs(off))] = True
    pad = math.atan2(max(float(extent_m), 0.0), r_obj)
    hidden = 0
    for side in (1.0, -1.0):
        s = side * off
        near = np.flatnonzero((s > half) & (s <= half + pad))
        run = blocked[near[np.argsort(s[near])]]
        hidden += int(len(run) if run.all() else np.argmin(run))
    seen = int(np.count_nonzero(inside & ~blocked))
    return seen / float(np.count_nonzero(inside) + hidden)
