"""Association (the paper's assumption 5): which tracked object a candidate or a box is.

:func:`associate` matches a frame's candidate (points, a ground-plane placement) with a tracked object
of its class (a candidate of a box about as wide as the image joins one or is dropped: :func:`wide_box`);
:func:`sighting` and :func:`bearing_match` let a box that gave no object still see an
object the LIDAR has confirmed (bearing-only association).
"""

from __future__ import annotations

import math

import numpy as np

from app.ocslam.candidate import Candidate
from app.ocslam.classes import prior
from app.ocslam.config import ConsciousnessConfig
from app.ocslam.free_space import FreeFn, gap_seen_free
from app.ocslam.projection import BoundingArea
from app.ocslam.proximity import along_ray_close, angle_wrap, contiguous, min_distance
from app.ocslam.se2 import Pose2
from app.ocslam.tracks import Sighting, Track


def associate(
    cand: Candidate, tracks: list[Track], stamp: float, cfg: ConsciousnessConfig, known_free: FreeFn | None = None
) -> Track | None:
    """The tracked object of the candidate's class it is (paper's assumption 5), or ``None``.

    Nearest centre within ``tracking_threshold_m``, or the object's footprint (grown by half the
    threshold) holding the candidate's centre — when both have LIDAR points, only if some of them lie
    within half the threshold of each other — or half its points, or the candidate's footprint
    holding the object's centre; ground-plane placements along the line of sight; partial views
    that continue the object's points — unless the map saw free floor between them (``known_free``,
    ``consciousness.gap_seen_free``). Never an object another box of this frame already updated."""
    thr = float(cfg.tracking_threshold_m)
    best, best_d = None, math.inf
    c = cand.center
    partial = cand.ray_weight == 0.0
    for t in tracks:
        if t.label != cand.label or t.footprint is None:
            continue
        if t.boxes.get(stamp, cand.area_index) != cand.area_index:
            continue  # already seen in this frame through another box: another instance
        v = t.footprint.center - c
        d = math.sqrt(float(v.dot(v)))  # np.linalg.norm's value (its dot product), without its overhead
        match = d < thr or t.footprint.contains_point(c, margin=0.5 * thr)
        if match and len(cand.points) and t.evidence.has_points and min_distance(cand.points, t.evidence.points) > 0.5 * thr:
            # near, yet no point of it near the object's points: the LIDAR shows two things (a ball in
            # front of a partition is not the false ball behind it that its centre is close to)
            match = False
        if not match and len(cand.points):
            # at least half of the candidate's points inside (np.mean ≥ 0.5, in integers)
            match = 2 * int(np.count_nonzero(t.footprint.contains(cand.points, margin=0.5 * thr))) >= len(cand.points)
        if not match and cand.footprint is not None:
            match = cand.footprint.contains_point(t.footprint.center)
        if not match and (cand.source == "ground_plane" or not t.evidence.has_points) and cand.ray_origin is not None:
            # ground-plane ranging is uncertain along the line of sight (a few pixels of the bottom
            # edge), not across it
            match = along_ray_close(cand.ray_origin, cand.center, t.footprint.center, thr)
        if not match and (partial or t.partial_only) and len(cand.points):
            # a partial view of a large object: its points continue the object's (one of its
            # typical shapes holds both)
            # ... on the side where the box is cut: nothing of the object lies beyond its closed edge
            closed_ok = not cfg.point_ownership or cand.beyond_closed_edge(t.evidence.points) <= 0.2
            match = closed_ok and contiguous(
                cand.points, t.evidence.points, t.prior, t.prior.length[2], typical=True
            )
            if match and cfg.gap_seen_free and gap_seen_free(cand.points, t.evidence.points, t.prior, known_free):
                match = False  # free floor seen between them: two objects (an armchair and a sofa's face)
            if match:
                d = thr + float(min_distance(cand.points, t.evidence.points))
        if match and d < best_d:
            best, best_d = t, d
    return best


def wide_box(cols: tuple[float, float] | None, image_width: float, fraction: float) -> bool:
    """True if a box's columns ``(x1, x2)`` (pixels) span at least ``fraction`` of the image's width
    (``fraction`` ≥ 1 or unknown columns: never). Such a box shows little or nothing of its object's sides:
    the camera is too close to see its extent, and a detector fires so at surfaces filling the view (a wall, a
    shelf's side), so it may confirm an object made before but makes none."""
    if cols is None or fraction >= 1.0 or image_width <= 0:
        return False
    return float(cols[1]) - float(cols[0]) >= fraction * float(image_width)


def sighting(area: BoundingArea, T_map_scan: Pose2, stamp: float, kf: int, cfg: ConsciousnessConfig) -> Sighting:
    """A box that gave no object, as a wedge in the map frame with the range its bottom edge allows."""
    pc = prior(area.label)
    tol = float(cfg.range_tolerance)
    apex = T_map_scan.transform_points(area.apex[None, :])[0]
    b = area.bearing_center + T_map_scan.yaw
    if area.bottom_reliable:
        r_lo = max(area.near_range_lo * (1.0 - tol) - 0.3, 0.0)
        hi = area.near_range_hi if np.isfinite(area.near_range_hi) else 3.0 * area.near_range_m
        r_hi = hi * (1.0 + tol) + pc.length[2]
    else:
        r_lo, r_hi = 0.0, 12.0
    cut = area.truncated["left"] or area.truncated["right"]
    return Sighting(
        area.label, area.confidence, stamp, kf, apex, np.array([np.cos(b), np.sin(b)]), area.half_angle,
        r_lo, r_hi, 0.0 if cut else 1.0, box_cols=area.columns,
    )


def bearing_match(sight: Sighting, tracks: list[Track], stamp: float, near: float) -> Track | None:
    """The tracked object of the sighting's class in its wedge: nearest the range its bottom edge
    gives (relative), then nearest its bisector."""
    best, best_cost = None, math.inf
    for t in tracks:
        if t.label != sight.label or t.footprint is None or t.touched_stamp == stamp:
            continue
        # only objects the LIDAR has confirmed (seen whole at least once, with points twice)
        if t.partial_only or (t.evidence.has_points and t.evidence.observations < 2):
            continue
        if not sight.holds(t.footprint.center):
            continue
        v = t.footprint.center - sight.apex
        off = abs(float(angle_wrap(np.arctan2(v[1], v[0]) - np.arctan2(sight.direction[1], sight.direction[0]))))
        r_front = max(float(np.hypot(v[0], v[1])) - 0.5 * min(t.footprint.size_x, t.footprint.size_y), 0.0)
        dr = abs(r_front - near) / max(near, 0.5) if math.isfinite(near) else 0.0
        cost = dr + off / max(sight.half_angle, 1e-3)
        if cost < best_cost:
            best, best_cost = t, cost
    return best
