"""Same-frame collisions (Algorithm 1 lines 7-25 on one frame's candidates, the paper's assumption 4): the order in
which a frame's boxes choose their islands, and what two candidates of one frame are to each other. Between tracked
objects, after the updates: :mod:`app.ocslam.collisions`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from app.ocslam.candidate import Candidate, FrameReport
from app.ocslam.classes import prior
from app.ocslam.collisions import shares_evidence
from app.ocslam.config import ConsciousnessConfig
from app.ocslam.evidence import ObjectEvidence
from app.ocslam.footprint_estimate import estimate_footprint
from app.ocslam.projection import BoundingArea
from app.ocslam.proximity import overlap_fraction

_TWO_DEGREES = np.deg2rad(2.0)


def ownership_order(areas: Sequence[BoundingArea]) -> list[int]:
    """The order in which a frame's boxes choose their objects: the most constrained first.

    A narrow box can only be explained by the few islands in its narrow wedge, a wide one has more
    choice (a chair's box inside a table's: the chair's legs are the chair's). Boxes of about the same
    angular width go nearest projection first (the paper's assumption 3: the near range of the bottom
    edge; a box cut at the bottom is nearest), then the higher confidence."""

    def key(k: int) -> tuple[float, float, float, int]:
        a = areas[k]
        r = float(a.near_range_lo) if math.isfinite(a.near_range_lo) else 0.0
        return (round(float(a.half_angle) / _TWO_DEGREES), r, -a.confidence, k)

    return sorted(range(len(areas)), key=key)


def one_island_class(label: str) -> bool:
    """True if an object of the class stands on one island of the LIDAR plane: not on legs (a chair's, a
    person's) and not an open frame whose sides are apart (a bookcase's panels, a door's jambs)."""
    pc = prior(label)
    return not pc.legged and not pc.open_span


def side_by_side(a: tuple[float, float], b: tuple[float, float], share: float = 0.25) -> bool:
    """True if two boxes' image columns ``(x1, x2)`` each reach beyond the other on their own side by at least
    ``share`` of the narrower box's width: two things side by side, however much they overlap. A box nested in
    another (the detector's part and whole of one object) is not."""
    (x1, x2), (y1, y2) = (a, b) if a[0] <= b[0] else (b, a)  # x: the box that starts further left
    gap = share * min(x2 - x1, y2 - y1)
    return y1 - x1 >= gap and y2 - x2 >= gap


def islands_apart(a: Candidate, b: Candidate) -> bool:
    """True if two candidates of one frame, of one class that stands on one island, chose islands of different
    clusters of the whole scan (a gap of at least the island threshold parts them along the scan) through boxes
    side by side (:func:`side_by_side`): two objects (two pots of flowers end to end), however near their
    centres and completed shapes."""
    if a.label != b.label or not one_island_class(a.label) or not a.clusters or not b.clusters:
        return False
    if a.box_cols is None or b.box_cols is None or not side_by_side(a.box_cols, b.box_cols):
        return False
    return a.clusters.isdisjoint(b.clusters)


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
            fa, fb = a.footprint, b.footprint
            if fa is None or fb is None:
                continue  # never: `live` holds footprints only, and a merge keeps a's
            d = float(np.linalg.norm(a.center - b.center))
            frac = overlap_fraction(fa, fb)
            if a.label == b.label:
                if (d < thr or frac >= ov) and not (cfg.islands_apart and islands_apart(a, b)):
                    # one object seen through two boxes: a absorbs b; a box that saw one small island on its
                    # centre line (a pedestal) saw all of the object the LIDAR can: the other box's island is
                    # something beside it (a stool)
                    if float(cfg.pedestal_fraction) > 0.0 and prior(a.label).pedestal and (a.support is True or b.support is True):
                        if a.support is not True:
                            a.points, a.support, a.legs, a.source = b.points, True, b.legs, b.source
                    else:
                        a.points = np.vstack([a.points, b.points])
                    a.confidence = max(a.confidence, b.confidence)
                    if len(a.points):
                        ev = ObjectEvidence()
                        ev.add_points(a.points)
                        if a.ray_origin is not None and a.ray_dir is not None:
                            ev.add_ray(a.ray_origin, a.ray_dir, max(a.ray_weight, 0.2), apparent_width=a.apparent_width,
                                       base_range=a.base_range)
                        a.footprint = estimate_footprint(ev, prior(a.label)) or a.footprint
                    b.status = "collision"
                    rep.reject("merged_in_frame")
            elif (frac >= max(ov, 0.5) or d < 0.5 * thr) and (
                not cfg.point_ownership or shares_evidence(a.points, b.points, cfg)
            ):
                if abs(a.near_range - b.near_range) > 1e-6:
                    loser = b if a.near_range < b.near_range else a
                else:
                    loser = b if a.confidence >= b.confidence else a
                loser.status = "collision"
                rep.reject("collision")
