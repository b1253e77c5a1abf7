"""Collisions (Algorithm 1 lines 7-25, the paper's assumption 4: two objects cannot overlap).

Within one frame between the candidates of its boxes, and after the updates between tracked objects.
"""

from __future__ import annotations

import numpy as np

from app.ocslam.candidate import Candidate, FrameReport
from app.ocslam.classes import prior
from app.ocslam.config import ConsciousnessConfig
from app.ocslam.footprint import ObjectEvidence, estimate_footprint
from app.ocslam.tracks import FreeFn, Track, along_ray_close, co_observed, contiguous, merge_tracks, overlap_fraction


def resolve_frame_collisions(cands: list[Candidate | None], cfg: ConsciousnessConfig, rep: FrameReport) -> None:
    """Same-frame collisions (Algorithm 1 lines 7-25 on this frame's candidates): same class and
    overlapping → one object seen through two boxes (merged); different classes overlapping → the one
    whose projection is nearer the camera stays, else the higher confidence. Losers get
    ``status = "collision"``."""
    thr = float(cfg.tracking_threshold_m)
    ov = float(cfg.overlap_fraction)
    live = [c for c in cands if c is not None and c.footprint is not None]
    for i, a in enumerate(live):
        for b in live[i + 1 :]:
            if a.status == "collision" or b.status == "collision":
                continue
            d = float(np.linalg.norm(a.center - b.center))
            frac = overlap_fraction(a.footprint, b.footprint)  # type: ignore[arg-type]
            if a.label == b.label:
                if d < thr or frac >= ov:
                    # one object seen through two boxes: a absorbs b
                    a.points = np.vstack([a.points, b.points])
                    a.confidence = max(a.confidence, b.confidence)
                    if len(a.points):
                        ev = ObjectEvidence()
                        ev.add_points(a.points)
                        if a.ray_origin is not None:
                            ev.add_ray(a.ray_origin, a.ray_dir, max(a.ray_weight, 0.2), apparent_width=a.apparent_width)
                        a.footprint = estimate_footprint(ev, prior(a.label)) or a.footprint
                    b.status = "collision"
                    rep.reject("merged_in_frame")
            elif frac >= max(ov, 0.5) or d < 0.5 * thr:
                if abs(a.near_range - b.near_range) > 1e-6:
                    loser = b if a.near_range < b.near_range else a
                else:
                    loser = b if a.confidence >= b.confidence else a
                loser.status = "collision"
                rep.reject("collision")


def resolve_track_collisions(
    tracks: list[Track],
    touched: list[Track],
    stamp: float,
    cfg: ConsciousnessConfig,
    known_free: FreeFn | None,
    rep: FrameReport,
) -> list[Track]:
    """Tracked-object collisions after a frame's updates; returns the tracks that remain.

    Same class and overlapping (or pieces of one object: contiguous and together one of the class's
    typical shapes) → merged, unless seen side by side through two boxes of one frame; different
    classes overlapping by half the smaller → the nearer projection if both were seen now, else the
    one with more evidence (ties: the older)."""
    thr = float(cfg.tracking_threshold_m)
    ov = float(cfg.overlap_fraction)
    removed: set[int] = set()
    for a in touched:
        if a.id in removed or a.footprint is None:
            continue
        for b in list(tracks):
            if b is a or b.id in removed or b.footprint is None:
                continue
            d = float(np.linalg.norm(a.footprint.center - b.footprint.center))
            reach = 0.5 * (np.hypot(a.footprint.size_x, a.footprint.size_y) + np.hypot(b.footprint.size_x, b.footprint.size_y))
            if d > reach + thr:
                continue
            frac = overlap_fraction(a.footprint, b.footprint)
            if a.label == b.label:
                same = d < thr or frac >= ov
                if not same:
                    # pieces of one object seen from different sides or only in parts (cut by the
                    # image border): close (touching; within the class's length for partial views)
                    # and together one object of the class
                    gap = a.prior.length[2] if (a.partial_only or b.partial_only) else thr
                    same = contiguous(a.evidence.points, b.evidence.points, a.prior, gap, typical=True)
                if not same and (not a.evidence.has_points or not b.evidence.has_points):
                    gp, other = (a, b) if not a.evidence.has_points else (b, a)
                    if len(gp.evidence.ray_origin):
                        same = along_ray_close(gp.evidence.ray_origin[-1], gp.footprint.center, other.footprint.center, thr)
                if same and co_observed(a, b):
                    same = False  # seen side by side through two boxes in one frame: two objects
                if same:
                    keep, drop = (a, b) if (a.presence, a.frames, a.detections) >= (b.presence, b.frames, b.detections) else (b, a)
                    merge_tracks(keep, drop, cfg, known_free)
                    removed.add(drop.id)
                    rep.merged += 1
                    if drop is a:
                        break
            elif frac >= max(ov, 0.5):
                both_now = a.touched_stamp == stamp and b.touched_stamp == stamp
                if both_now and abs(a.near_range - b.near_range) > 1e-6:
                    drop = b if a.near_range < b.near_range else a
                else:
                    # more evidence wins; on a tie the incumbent (older) object stays
                    ka = (a.presence, a.frames, a.detections, -a.created)
                    kb = (b.presence, b.frames, b.detections, -b.created)
                    drop = b if ka >= kb else a
                removed.add(drop.id)
                rep.removed += 1
                if drop is a:
                    break
    if removed:
        tracks = [t for t in tracks if t.id not in removed]
    return tracks
