"""SLAM accuracy metrics: the Kümmerle et al. (2009) relation metric, ATE RMSE, map agreement.

Relation metric ("On measuring the accuracy of SLAM algorithms", Autonomous Robots 27(4), 2009): for
every ground-truth relation ``(t1, t2, δ)`` take the estimated poses ``P1``, ``P2`` at the two stamps,
``d = P1⁻¹ ∘ P2``, translational error ``‖d.t − δ.t‖`` and rotational error ``|wrap(d.yaw − δ.yaw)|``;
report mean ± std of the absolute and of the squared errors.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from app.ocslam.messages import OccupancyGrid
from app.ocslam.se2 import between, interpolate, wrap_angle


@dataclass
class Relations:
    """Ground-truth relations: stamps ``t1``, ``t2`` ``(R,)`` and motions ``(R, 3)`` ``(x, y, yaw)`` in the t1 frame."""

    t1: NDArray[np.float64]
    t2: NDArray[np.float64]
    motion: NDArray[np.float64]

    def __len__(self) -> int:
        return len(self.t1)


def read_relations(path: str | Path) -> Relations:
    """Read a ``.relations`` file (``t1 t2 x y z roll pitch yaw`` per line; malformed lines are skipped)."""
    rows = []
    with open(path) as fh:
        for line in fh:
            tok = line.split()
            if len(tok) < 8 or tok[0].startswith("#"):
                continue
            try:
                rows.append([float(tok[i]) for i in (0, 1, 2, 3, 7)])
            except ValueError:
                continue
    a = np.array(rows, np.float64).reshape(-1, 5)
    return Relations(a[:, 0], a[:, 1], a[:, 2:5].copy())


@dataclass
class RelationErrors:
    """Per-relation errors ``trans`` (m) and ``rot`` (rad), ``(R,)``, and their summary."""

    trans: NDArray[np.float64]
    rot: NDArray[np.float64]

    def summary(self) -> dict[str, float]:
        t, r = self.trans, np.degrees(self.rot)
        return {
            "relations": int(len(t)),
            "trans_mean_m": float(t.mean()),
            "trans_std_m": float(t.std()),
            "trans_sq_mean_m2": float((t**2).mean()),
            "trans_sq_std_m2": float((t**2).std()),
            "rot_mean_deg": float(r.mean()),
            "rot_std_deg": float(r.std()),
            "rot_sq_mean_deg2": float((r**2).mean()),
            "rot_sq_std_deg2": float((r**2).std()),
        }


def relation_errors(stamps: NDArray[np.float64], poses: NDArray[np.float64], rel: Relations, max_gap_s: float = 1e-3) -> RelationErrors:
    """Errors of the trajectory ``stamps (N,)``, ``poses (N, 3)`` against ``rel``.

    Poses are looked up at exactly the relation stamps when the trajectory has them (within
    ``max_gap_s``), else interpolated.
    """
    stamps = np.asarray(stamps, np.float64)
    poses = np.asarray(poses, np.float64).reshape(-1, 3)

    def at(t):
        i = np.clip(np.searchsorted(stamps, t), 0, len(stamps) - 1)
        j = np.clip(i - 1, 0, len(stamps) - 1)
        i = np.where(np.abs(stamps[j] - t) < np.abs(stamps[i] - t), j, i)
        exact = np.abs(stamps[i] - t) <= max_gap_s
        return np.where(exact[:, None], poses[i], interpolate(t, stamps, poses))

    d = between(at(rel.t1), at(rel.t2))
    trans = np.hypot(d[:, 0] - rel.motion[:, 0], d[:, 1] - rel.motion[:, 1])
    rot = np.abs(wrap_angle(d[:, 2] - rel.motion[:, 2]))
    return RelationErrors(trans, np.asarray(rot))


def ate_rmse(est: NDArray[np.float64], gt: NDArray[np.float64]) -> float:
    """Absolute trajectory error: RMS of the position differences of matched ``(N, 3)`` poses (same frame, no alignment)."""
    est = np.asarray(est, np.float64).reshape(-1, 3)
    gt = np.asarray(gt, np.float64).reshape(-1, 3)
    if len(est) != len(gt):
        raise ValueError(f"ate_rmse: {len(est)} estimated vs {len(gt)} true poses")
    if len(est) == 0:
        return float("nan")
    return float(np.sqrt(np.mean(np.sum((est[:, :2] - gt[:, :2]) ** 2, axis=1))))


def rasterize_polygons(grid: OccupancyGrid, polygons: list[NDArray[np.float64]]) -> NDArray[np.bool_]:
    """``(H, W)`` True where a cell's area touches any ``(K, 2)`` polygon (given in the grid's frame)."""
    mask = np.zeros((grid.height, grid.width), np.uint8)
    inv = grid.origin.inverse()
    for poly in polygons:
        p = np.asarray(poly, np.float64).reshape(-1, 2)
        if len(p) < 2:
            continue
        uv = inv.transform_points(p) / grid.resolution  # (x → col, y → row), continuous
        # fixed-point coordinates for sub-cell precision; cell (r, c) spans [c, c+1): shift by -0.5 so
        # OpenCV's pixel-centre convention matches, and draw the outline too so thin walls are kept
        pts = np.round((uv - 0.5) * 16).astype(np.int32).reshape(-1, 1, 2)
        cv2.fillPoly(mask, [pts], 1, lineType=cv2.LINE_8, shift=4)
        cv2.polylines(mask, [pts], True, 1, lineType=cv2.LINE_8, shift=4)
    return mask.astype(bool)


def map_agreement(
    grid: OccupancyGrid, obstacle_polygons: list[NDArray[np.float64]], occupied_thresh: int = 65
) -> tuple[float, float]:
    """Precision and recall of the grid's occupied cells against the true obstacles, within one cell.

    Args:
        grid: the estimated map.
        obstacle_polygons: ``(K, 2)`` true wall/obstacle outlines in the grid's frame.
        occupied_thresh: cells with occupancy ≥ this (0..100) count as occupied.

    Precision: fraction of occupied cells within one cell (8-neighbourhood) of a true obstacle cell.
    Recall: fraction of the true obstacles' *boundary* cells that were observed (not unknown) and lie
    within one cell of an occupied cell — the LIDAR only ever sees surfaces, so interiors are excluded.
    """
    occ = grid.data >= occupied_thresh
    truth = rasterize_polygons(grid, obstacle_polygons)
    k = np.ones((3, 3), np.uint8)
    truth_d = cv2.dilate(truth.astype(np.uint8), k).astype(bool)
    occ_d = cv2.dilate(occ.astype(np.uint8), k).astype(bool)
    n_occ = int(occ.sum())
    precision = float((occ & truth_d).sum()) / n_occ if n_occ else float("nan")
    boundary = truth & ~cv2.erode(truth.astype(np.uint8), k, borderType=cv2.BORDER_CONSTANT, borderValue=0).astype(bool)
    seen = boundary & cv2.dilate((grid.data >= 0).astype(np.uint8), k).astype(bool)
    n_b = int(seen.sum())
    recall = float((seen & occ_d).sum()) / n_b if n_b else float("nan")
    return precision, recall
