"""Collisions between tracked objects (Algorithm 1 lines 7-25, the paper's assumption 4: two objects cannot
overlap), after a frame's updates: merges of one object's pieces, points shared by two objects, a corner leg.
The same rule between one frame's candidates is :mod:`app.ocslam.frame_collisions`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from app.ocslam.candidate import FrameReport
from app.ocslam.config import ConsciousnessConfig
from app.ocslam.footprint import min_area_rect, rect_corners_near
from app.ocslam.free_space import FreeFn, gap_seen_free
from app.ocslam.proximity import along_ray_close, contiguous, fits_instance, overlap_fraction
from app.ocslam.tracks import Track, co_observed, merge_tracks, pedestal, seen_apart

FloatArray = NDArray[np.float64]


def strong_points(t: Track) -> FloatArray:
    """``(K, 2)`` the object's well-seen evidence points (voxels seen in at least a tenth of the best one's frames)."""
    ev = t.evidence
    if not ev.has_points:
        return ev.points
    return ev.points[ev.hits >= max(1.0, 0.1 * float(ev.hits.max()))]


def one_instance(
    a: Track, b: Track, fragment_fits_largest: bool = False, pedestal_fraction: float = 0.0, box_widths: bool = False,
    told_only: bool = False,
) -> bool:
    """True if two same-class objects' well-seen points together fit one instance of the class (one
    of its typical shapes; for legs seen as legs, the legs of one instance; for an object on a pedestal
    (:func:`~app.ocslam.tracks.pedestal` at ``pedestal_fraction``), that one support). With ``fragment_fits_largest``,
    when either was only seen through border-cut boxes (a fragment), its largest instance is enough (the
    other's points may overstate its shape). With ``box_widths``, the instance must also be no wider than
    the two objects' boxes show it (:func:`wider_than_boxes`). ``told_only``: a pedestal's share is of the views that
    told (``consciousness.support_whole_boxes``). Without points on either side only their footprints can tell: True."""
    pa, pb = strong_points(a), strong_points(b)
    if len(pa) == 0 or len(pb) == 0:
        return True
    both = np.vstack([pa, pb])
    _th, lo, hi = min_area_rect(both)
    d = hi - lo
    pc = a.prior
    if not fits_instance(pc, float(d[0]), float(d[1]), typical=not (fragment_fits_largest and (a.partial_only or b.partial_only))):
        return False
    if box_widths and wider_than_boxes(a, b, both):
        return False
    if pc.legged and float(max(d)) > pc.leg_size_max * 1.5 and any(
        pedestal(t.evidence, p, pc, pedestal_fraction, told_only) for t, p in ((a, pa), (b, pb))
    ):
        return False  # a pedestal's points are its support alone: the rest is another object's
    legs = pc.legged and all(t.evidence.leg_obs * 2 > t.evidence.observations for t in (a, b))
    return not legs or pc.legs_fit(float(d[0]), float(d[1]))


def wider_than_boxes(a: Track, b: Track, points: FloatArray | None = None) -> bool:
    """True if ``points`` ``(N, 2)`` (map frame; by default both objects' :func:`strong_points`) spread wider across most of the two objects' lines of sight than
    their boxes showed there: principle 21's cap (``box_width_cap`` × a box's apparent width, and 0.2 m more) for
    each bisector ray of a box not cut by the image border. The class's shapes reach from a dining chair to a
    2.2 m sofa, so two chairs' points may fit "one chair"; their boxes, each a chair wide, say otherwise.
    False when the cap is off or no ray knows its box's width."""
    k = float(a.evidence.box_width_cap)
    if k <= 0.0:
        return False
    if points is None:
        points = np.vstack([strong_points(a), strong_points(b)])
    if len(points) == 0:
        return False
    dirs, widths = [], []
    for ev in (a.evidence, b.evidence):
        m = (ev.ray_open == 0) & np.isfinite(ev.ray_app) & (ev.ray_app > 0.0)
        dirs.append(ev.ray_dir[m])
        widths.append(ev.ray_app[m])
    w = np.concatenate(widths)
    if len(w) == 0:
        return False
    d = np.vstack(dirs)
    across = points @ np.stack([-d[:, 1], d[:, 0]])  # (N, R): each point's offset across each ray
    span = across.max(axis=0) - across.min(axis=0)
    return bool(np.count_nonzero(span > np.maximum(k * w, w + 0.2)) * 2 > len(w))


def shared_gap(cfg: ConsciousnessConfig) -> float:
    """How near a point must lie to another object's to be on it (m): half the island gap, at least 3 cm."""
    return max(0.5 * float(cfg.island_threshold_m), 0.03)


#: Point sets up to this many pairs are compared all pairs at once, larger ones on KD-trees.
_ALL_PAIRS_MAX = 40_000


def shared_fractions(a: FloatArray, b: FloatArray, cfg: ConsciousnessConfig) -> tuple[float, float]:
    """``(share of a's points on b's, share of b's on a's)``, "on" = within half the island gap.

    Small sets compare all pairs' squared distances; a pair within a relative 1e-9 of the gap (where
    the rounding of the distance might decide) sends the whole test to the KD-trees' distances."""
    if len(a) == 0 or len(b) == 0:
        return 0.0, 0.0
    gap = shared_gap(cfg)
    if len(a) * len(b) <= _ALL_PAIRS_MAX:
        dx = a[:, 0, None] - b[None, :, 0]
        dy = a[:, 1, None] - b[None, :, 1]
        d2 = dx * dx + dy * dy
        da2, db2 = d2.min(axis=1), d2.min(axis=0)
        g2 = gap * gap
        if not (np.abs(np.concatenate([da2, db2]) - g2) <= 1e-9 * g2).any():
            # the shares as np.mean gives them: the count over the size, one rounding
            return np.count_nonzero(da2 < g2) / len(a), np.count_nonzero(db2 < g2) / len(b)
    da, _ = cKDTree(b).query(a, k=1)
    db, _ = cKDTree(a).query(b, k=1)
    return float(np.mean(da <= gap)), float(np.mean(db <= gap))


def strip_points(t: Track, other: FloatArray, cfg: ConsciousnessConfig, known_free: FreeFn | None) -> bool:
    """Remove from ``t``'s evidence the voxels lying on ``other``'s points (they are the other object's);
    True if ``t`` keeps well-seen points of its own (its footprint is re-estimated)."""
    ev = t.evidence
    gap = shared_gap(cfg)
    d, _ = cKDTree(other).query(ev.points, k=1)
    keep = d > gap
    ev.keep_points(keep)
    if not ev.has_points:
        return False
    t.refresh(known_free)
    return t.footprint is not None


def split_shared(a: Track, b: Track, cfg: ConsciousnessConfig, known_free: FreeFn | None) -> list[Track]:
    """Two objects on some of the same LIDAR points: each voxel within half the island gap of the other's
    stays with the one that saw it in more frames (both keep it on a tie); returns those left with no
    point of their own (their footprints are re-estimated otherwise)."""
    ea, eb = a.evidence, b.evidence
    gap = shared_gap(cfg)
    da, ia = cKDTree(eb.points).query(ea.points, k=1)
    db, ib = cKDTree(ea.points).query(eb.points, k=1)
    a_loses = (da <= gap) & (ea.hits < eb.hits[ia])
    b_loses = (db <= gap) & (eb.hits < ea.hits[ib])
    lost = []
    for t, loses in ((a, a_loses), (b, b_loses)):
        if not loses.any():
            continue
        t.evidence.keep_points(~loses)
        if not t.evidence.has_points:
            lost.append(t)
            continue
        t.refresh(known_free)
    return lost


def shares_evidence(a: FloatArray, b: FloatArray, cfg: ConsciousnessConfig) -> bool:
    """True if two objects rest on the same LIDAR evidence: at least ``shared_evidence_fraction`` of the
    smaller point set lies within half the island gap of the other (or either has no points, when only
    their footprints can tell). Objects of different classes side by side (a chair pushed under a
    table) have their own points and do not collide."""
    if len(a) == 0 or len(b) == 0:
        return True
    small, big = (a, b) if len(a) <= len(b) else (b, a)
    d, _ = cKDTree(big).query(small, k=1)
    gap = shared_gap(cfg)
    return float(np.mean(d <= gap)) >= float(cfg.shared_evidence_fraction)


def border_piece_of(a: Track, b: Track, cfg: ConsciousnessConfig) -> Track | None:
    """Of two objects of different classes, the one that is a piece of the other, or None: an object that
    sits in a wall (a door, ``ClassPrior.on_wall``) only ever seen through boxes cut by the image border,
    whose points continue a free-standing object seen whole (within the island gap) into no more than that
    class's largest instance. A box at the image's edge shows only a strip of what it boxed (a bookcase's
    side taken for a door); a door's points continue a wall, not a piece of furniture."""
    if a.partial_only == b.partial_only:
        return None
    piece, whole = (a, b) if a.partial_only else (b, a)
    if not piece.prior.on_wall or whole.prior.on_wall:
        return None  # free-standing objects touch (a chair pushed to a table's leg); a door is part of a wall
    gap = float(cfg.island_threshold_m)
    return piece if contiguous(piece.evidence.points, whole.evidence.points, whole.prior, gap) else None


def corner_leg(small: Track, small_pts: FloatArray, big: Track, big_pts: FloatArray, cfg: ConsciousnessConfig) -> bool:
    """True if the points a smaller solid object (``small``, of a class without legs) shares with ``big`` are
    ``big``'s own leg: ``big`` is legged furniture seen as legs in most of its views, and every shared point
    (of ``small_pts`` within half the island gap of ``big_pts``; both ``(K, 2)`` well-seen points, ``map``)
    lies within ``leg_corner_m`` of one and the same corner of the rectangle of ``big``'s points, where a leg
    stands (the shape prior of :func:`~app.ocslam.area_candidate.corner_legs`). A chair pushed under a
    table's edge shares the legs between the table's corners, a person's leg stands beside a chair's; a
    false table made of a chair's legs shares them at all its corners."""
    corner_m = float(cfg.leg_corner_m)
    ev = big.evidence
    if not cfg.corner_leg_owner or corner_m <= 0.0 or small.prior.legged or not big.prior.legged:
        return False
    if 2 * ev.leg_obs <= ev.observations or len(big_pts) < 3:
        return False
    d, _ = cKDTree(big_pts).query(small_pts, k=1)
    on = small_pts[d <= shared_gap(cfg)]
    if len(on) == 0:
        return False
    dist, corner = rect_corners_near(on, min_area_rect(big_pts))
    return bool(np.all(corner == corner[0]) and np.all(dist <= corner_m))


def _sharing(a: Track, b: Track, cfg: ConsciousnessConfig) -> tuple[FloatArray, FloatArray] | None:
    """Both objects' well-seen points (:func:`strong_points`) if at least ``shared_evidence_fraction`` of
    one's lie on the other's, else None."""
    pa, pb = strong_points(a), strong_points(b)
    sa, sb = shared_fractions(pa, pb, cfg)
    return (pa, pb) if max(sa, sb) >= float(cfg.shared_evidence_fraction) else None


def _merge(a: Track, b: Track, cfg: ConsciousnessConfig, known_free: FreeFn | None, removed: set[int], rep: FrameReport) -> Track:
    """Merge two same-class objects into the one with more evidence; returns the one merged away."""
    keep, drop = (a, b) if (a.presence, a.frames, a.detections) >= (b.presence, b.frames, b.detections) else (b, a)
    merge_tracks(keep, drop, cfg, known_free)
    removed.add(drop.id)
    rep.merged += 1
    return drop


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
    if not touched:
        return tracks
    order = list(tracks)
    # the footprints now, for a quick test of every pair at once: pairs surely farther apart than
    # their reach are skipped (a footprint re-estimated since then is tested one by one)
    fps = [t.footprint for t in order]
    centers = np.array([fp.center if fp is not None else (np.nan, np.nan) for fp in fps], dtype=np.float64).reshape(-1, 2)
    radii = np.array([fp.circumradius if fp is not None else np.nan for fp in fps])
    for a in touched:
        if a.id in removed or a.footprint is None:
            continue
        fa0 = a.footprint
        gaps = np.hypot(centers[:, 0] - fa0.center[0], centers[:, 1] - fa0.center[1])
        far_apart = (gaps > fa0.circumradius + radii + thr + 1e-6).tolist()
        for k, b in enumerate(order):
            fa, fb = a.footprint, b.footprint  # a's may be re-estimated by a merge, never unset
            if far_apart[k] and fa is fa0 and fb is fps[k]:
                continue  # d > reach + thr below, surely
            if b is a or b.id in removed or fa is None or fb is None:
                continue
            d = float(np.linalg.norm(fa.center - fb.center))
            reach = 0.5 * (np.hypot(fa.size_x, fa.size_y) + np.hypot(fb.size_x, fb.size_y))
            if d > reach + thr:
                continue
            # the footprints' overlap_fraction is computed only on the branches that use it
            if a.label == b.label:
                if co_observed(a, b):
                    # seen side by side through two boxes in one frame: two objects, however close,
                    # unless they rest on the same LIDAR points (one box's island was the other's object)
                    if not (cfg.point_ownership and a.evidence.has_points and b.evidence.has_points):
                        continue
                    shared = _sharing(a, b, cfg)
                    if shared is None:
                        continue
                    if seen_apart(a, b, int(cfg.seen_apart_frames)):
                        # side by side through separate boxes, frame after frame: two objects whose points mix
                        # (a round table's and the stools between it and the next); each keeps what it saw more
                        lost = [t for t in split_shared(a, b, cfg, known_free) if t.id not in removed]
                        for t in lost:
                            removed.add(t.id)
                            rep.removed += 1
                        if a in lost:
                            break
                        continue
                    apart = cfg.islands_apart and (b.id in a.apart or a.id in b.apart)
                    if apart or not one_instance(a, b, cfg.fragment_fits_largest, float(cfg.pedestal_fraction), cfg.union_width_check,
                                                     told_only=cfg.support_whole_boxes):
                        # together larger than one instance: the larger loses the shared points (as a
                        # nested object's, below) and stays if it keeps points of its own; a pedestal's support
                        # is its own whatever its footprint (principle 16: its cross-section is that support)
                        loser, other_pts = (a, shared[1]) if fa.area >= fb.area else (b, shared[0])
                        ped_a, ped_b = (pedestal(t.evidence, q, t.prior, float(cfg.pedestal_fraction), cfg.support_whole_boxes)
                                        for t, q in ((a, shared[0]), (b, shared[1])))
                        if ped_a != ped_b:
                            loser, other_pts = (b, shared[0]) if ped_a else (a, shared[1])
                        if not strip_points(loser, other_pts, cfg, known_free):
                            removed.add(loser.id)
                            rep.removed += 1
                            if loser is a:
                                break
                        continue
                    if _merge(a, b, cfg, known_free, removed, rep) is a:
                        break
                    continue
                same = d < thr or overlap_fraction(fa, fb) >= ov
                if same and cfg.point_ownership and not one_instance(
                    a, b, cfg.fragment_fits_largest, float(cfg.pedestal_fraction), told_only=cfg.support_whole_boxes
                ):
                    # overlapping, but together larger than any instance: two objects, unless each stands
                    # on the other's centre (two solid objects cannot interpenetrate: one of them holds
                    # foreign points)
                    same = fa.contains_point(fb.center) and fb.contains_point(fa.center)
                if not same:
                    # pieces of one object seen from different sides or only in parts (cut by the
                    # image border): close (touching; within the class's length for partial views)
                    # and together one object of the class
                    fragment = a.partial_only or b.partial_only
                    gap = a.prior.length[2] if fragment else thr
                    # a fragment (seen only through border-cut boxes) need only fit the class's largest
                    # instance with its neighbour: the neighbour's own points may overstate its shape
                    typical = not (cfg.fragment_fits_largest and fragment)
                    same = contiguous(a.evidence.points, b.evidence.points, a.prior, gap, typical=typical)
                    if same and cfg.gap_seen_free and gap_seen_free(a.evidence.points, b.evidence.points, a.prior, known_free):
                        same = False  # the map saw free floor between them: two objects
                    if same and cfg.fragment_width_check and wider_than_boxes(a, b):
                        same = False  # together wider than their whole boxes showed either: two objects
                if not same and (not a.evidence.has_points or not b.evidence.has_points):
                    (gp, gp_fp), other_fp = ((a, fa), fb) if not a.evidence.has_points else ((b, fb), fa)
                    if len(gp.evidence.ray_origin):
                        same = along_ray_close(gp.evidence.ray_origin[-1], gp_fp.center, other_fp.center, thr)
                if same and _merge(a, b, cfg, known_free, removed, rep) is a:
                    break
            elif cfg.point_ownership and a.evidence.has_points and b.evidence.has_points:
                # Objects of different classes, both with LIDAR points: ownership of the points they
                # share. Side by side (each on its own points) both stay. One nested in the other
                # (a chair pushed under a table's edge) keeps the shared points, the larger loses
                # them. Otherwise (two labels on one object) the one with more evidence stays.
                shared = _sharing(a, b, cfg)
                if shared is None:
                    piece = border_piece_of(a, b, cfg) if cfg.border_fragment_of_other else None
                    if piece is not None:
                        removed.add(piece.id)
                        rep.removed += 1
                        if piece is a:
                            break
                    continue
                (small, small_fp, small_pts), (big, big_fp) = (
                    ((a, fa, shared[0]), (b, fb)) if fa.area <= fb.area else ((b, fb, shared[1]), (a, fa))
                )
                if small_fp.area < 0.5 * big_fp.area and not small.partial_only:
                    big_pts = shared[1] if small is a else shared[0]
                    # the shared points go to their owner: a legged object's leg at its corner is its own (flowers
                    # seen behind a desk's corner leg), and a confirmed object's against a nested one not yet
                    # confirmed (principle 5: evidence over frames; a first glimpse of a chair behind a round table
                    # does not take its pedestal); else the nested object's (a chair's legs under a table's edge)
                    if corner_leg(small, small_pts, big, big_pts, cfg) or (
                        cfg.nested_unconfirmed and small.presence < float(cfg.presence_threshold) <= big.presence
                    ):
                        loser, lost_pts = small, big_pts
                    else:
                        loser, lost_pts = big, small_pts
                    if strip_points(loser, lost_pts, cfg, known_free):
                        continue
                    drop = loser
                else:
                    ka = (a.complete_views > 0, a.presence, a.frames, a.detections, -a.created)
                    kb = (b.complete_views > 0, b.presence, b.frames, b.detections, -b.created)
                    drop = b if ka >= kb else a
                removed.add(drop.id)
                rep.removed += 1
                if drop is a:
                    break
            elif overlap_fraction(fa, fb) >= max(ov, 0.5):
                both_now = a.touched_stamp == stamp and b.touched_stamp == stamp
                if both_now and abs(a.near_range - b.near_range) > 1e-6:
                    drop = b if a.near_range < b.near_range else a
                else:
                    # more evidence wins; on a tie the incumbent (older) object stays
                    ea = (a.presence, a.frames, a.detections, -a.created)
                    eb = (b.presence, b.frames, b.detections, -b.created)
                    drop = b if ea >= eb else a
                removed.add(drop.id)
                rep.removed += 1
                if drop is a:
                    break
    if removed:
        tracks = [t for t in tracks if t.id not in removed]
    return tracks
