"""One frame's candidates (improved mode; paper §2.5.3, Algorithm 1 lines 2-25 on one frame): each LIDAR point given
to the boxes' bounding areas, the boxes nearest the camera choosing their island first (point ownership, the paper's
assumption 3: a chair's legs are not the table's), the object of each area (:func:`~app.ocslam.area_candidate.area_candidate`),
then the same-frame collisions between them."""

from __future__ import annotations

import numpy as np

from app.ocslam.area_candidate import area_candidate
from app.ocslam.camera import CameraModel
from app.ocslam.candidate import Candidate, FrameReport
from app.ocslam.config import ConsciousnessConfig
from app.ocslam.frame_collisions import one_island_class, ownership_order, resolve_frame_collisions
from app.ocslam.islands import close_pairs, cluster_extents
from app.ocslam.messages import OccupancyGrid
from app.ocslam.point_ownership import assign_points, contest_by_range
from app.ocslam.projection import BoundingArea
from app.ocslam.scan_beams import ScanBeams
from app.ocslam.se2 import Pose2


def frame_candidates(
    areas: list[BoundingArea],
    beams: ScanBeams,
    angle_increment: float,
    T_map_scan: Pose2,
    T_map_base: Pose2,
    grid: OccupancyGrid | None,
    rep: FrameReport,
    cfg: ConsciousnessConfig,
    cam: CameraModel,
) -> list[Candidate | None]:
    """The candidate of each bounding area of one frame (``None`` where no island passes; a loser of a same-frame
    collision has ``status = "collision"``), in the areas' order. ``beams``: the frame's scan (``base_scan``, and
    about the wedges' apex); sets each area's ``points`` and the report's ``islands`` and ``chosen``."""
    pts_all, valid, ranges = beams.points, beams.valid, beams.ranges
    beam_b_apex, beam_r_apex = beams.bearing_apex, beams.range_apex
    ownership = bool(cfg.point_ownership)
    member = assign_points(pts_all, areas, exclusive=not ownership, range_tolerance=float(cfg.range_tolerance))
    if ownership and float(cfg.range_contest_slack) < 2.0:
        member = contest_by_range(pts_all, areas, member, float(cfg.range_contest_slack))

    # the whole scan's clusters: an island clipped by its area may belong to a wall
    gap = float(cfg.island_threshold_m)
    scan_pairs = close_pairs(pts_all, gap) if areas else None  # one KD-tree a frame, shared by every area
    labels, extents = (
        cluster_extents(pts_all, gap, np.flatnonzero(valid), angle_increment, len(ranges), pairs_within_gap=scan_pairs)
        if areas
        else (None, None)
    )
    candidates: list[Candidate | None] = [None] * len(areas)
    rep.islands = [[] for _ in areas]
    # Point ownership: the boxes nearest the camera choose their object first (the paper's
    # assumption 3) and the islands it takes are no longer available to the boxes behind it (a
    # chair's legs are not the table's). Without ownership every point was given to one area by
    # its range alone (point_ownership.assign_points).
    owned = np.zeros(len(pts_all), dtype=bool)
    box_px = np.array([a.box_px for a in areas], dtype=np.float64).reshape(-1, 4)
    for k in ownership_order(areas) if ownership else range(len(areas)):
        area = areas[k]
        idx = np.flatnonzero(member[:, k] & ~owned)
        area.points = pts_all[idx]
        others = box_px[[j for j in range(len(areas)) if j != k and areas[j].label != area.label]] if ownership else None
        cand, isl = area_candidate(
            k, area, pts_all, idx, beam_b_apex, beam_r_apex, T_map_scan, T_map_base, grid, rep, cfg, cam, (labels, extents),
            others, scan_pairs,
        )
        rep.islands[k] = isl
        candidates[k] = cand
        if cfg.islands_apart and cand is not None and labels is not None and cand.islands and one_island_class(cand.label):
            # the scan clusters of its islands, for principle 37 (islands_apart reads them for these classes only)
            cand.clusters = frozenset(np.unique(labels[np.concatenate([isl[g].indices for g in cand.islands])]).tolist())
        if ownership and cand is not None:
            for g in cand.islands:
                owned[isl[g].indices] = True
    resolve_frame_collisions(candidates, cfg, rep)
    rep.chosen = candidates
    return candidates
