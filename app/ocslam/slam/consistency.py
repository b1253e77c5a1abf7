"""Map consistency without ground truth: do the scans of different visits agree?

Every keyframe's returns are put in the map frame at the keyframe's (corrected) pose. Keyframes are
grouped in blocks of ``block`` consecutive keyframes; for each return we look for the nearest return of a
*non-adjacent* block (another pass through the place, not the same few seconds). Returns with such a
neighbour within ``reach_m`` are *revisited*; the figure is the distribution of their distances: a
consistent map has its revisits within a few centimetres, a broken one (bent corridor, doubled walls)
has them spread up to ``reach_m``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from app.ocslam.se2 import transform_points


def revisit_consistency(
    poses: NDArray[np.float64], scans: list[NDArray[np.float64]], block: int = 25, reach_m: float = 0.5, k: int = 24, voxel_m: float = 0.05
) -> dict[str, float]:
    """Consistency of ``(K, 3)`` keyframe poses with their ``(P_k, 2)`` returns (base frame).

    Returns ``{"revisited_points", "median_m", "mean_m", "within_5cm", "within_10cm"}`` over the
    revisited returns (NaN when nothing is revisited).
    """
    pts, lab = [], []
    for kf, (p, s) in enumerate(zip(np.asarray(poses, np.float64).reshape(-1, 3), scans)):
        if len(s) == 0:
            continue
        w = transform_points(p, s)
        # one return per voxel per keyframe keeps dense near-range returns from dominating
        key = np.unique(np.floor(w / voxel_m).astype(np.int64), axis=0, return_index=True)[1]
        pts.append(w[key])
        lab.append(np.full(len(key), kf // block))
    if not pts:
        return {"revisited_points": 0, "median_m": float("nan"), "mean_m": float("nan"), "within_5cm": float("nan"), "within_10cm": float("nan")}
    P = np.vstack(pts)
    L = np.concatenate(lab)
    tree = cKDTree(P)
    d, idx = tree.query(P, k=min(k, len(P)), distance_upper_bound=reach_m)
    d = d.reshape(len(P), -1)
    idx = idx.reshape(len(P), -1)
    valid = np.isfinite(d)
    other = np.zeros_like(valid)
    other[valid] = np.abs(L[idx[valid]] - np.repeat(L, valid.shape[1]).reshape(valid.shape)[valid]) > 1
    dd = np.where(other, d, np.inf).min(axis=1)
    rv = np.isfinite(dd)
    x = dd[rv]
    if len(x) == 0:
        return {"revisited_points": 0, "median_m": float("nan"), "mean_m": float("nan"), "within_5cm": float("nan"), "within_10cm": float("nan")}
    return {
        "revisited_points": int(len(x)),
        "median_m": float(np.median(x)),
        "mean_m": float(np.mean(x)),
        "within_5cm": float(np.mean(x <= 0.05)),
        "within_10cm": float(np.mean(x <= 0.10)),
    }


__all__ = ["revisit_consistency"]
