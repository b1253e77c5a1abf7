"""Scan matching: multi-resolution correlative search (branch and bound), then continuous refinement.

1. :func:`correlative_search` finds the pose maximising the summed likelihood of the scan points in a
   :class:`~app.ocslam.slam.field.MatchField`, over a window of translations (whole cells) and rotations.
   It is the branch-and-bound of Hess et al. 2016 (Cartographer) run breadth-first and vectorised: at
   pyramid level ``h`` one candidate stands for ``2^h × 2^h`` translations and its score on the
   max-pooled grid bounds all of them; candidates whose bound cannot beat the best exact score found
   so far (a greedy dive to level 0) are pruned. The result is the exact optimum of the discrete search.
2. :func:`refine` polishes it to sub-cell accuracy by Gauss–Newton on point-to-line distances to the
   nearest map points (normals from the map), with a Cauchy robust kernel and an optional prior
   (the odometry prediction) — the continuous optimiser of Karto/Cartographer-style front ends.

Poses are ``(3,)`` arrays ``(x, y, yaw)`` of the scan's frame ``S`` in the field's frame ``F``; scan points
are ``(N, 2)`` in ``S``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from app.ocslam.se2 import wrap_angle
from app.ocslam.slam.field import MatchField


@dataclass
class SearchResult:
    pose: NDArray[np.float64]  # (3,) best pose of S in F
    score: float  # mean likelihood of the points at that pose, 0..1


@dataclass
class RefineResult:
    pose: NDArray[np.float64]  # (3,)
    inlier_fraction: float  # points within `inlier_m` of the map surface (of all points)
    rms_m: float  # RMS point-to-line distance of the inliers
    hessian: NDArray[np.float64]  # (3, 3) Gauss–Newton information of the scan term (without prior)
    iterations: int


def _rotated_cells(fld: MatchField, pts: NDArray[np.float64], xy: NDArray[np.float64], yaws: NDArray[np.float64]):
    """Integer cells ``(A, N)`` rows and cols of the points rotated by each yaw and translated by ``xy``."""
    c, s = np.cos(yaws)[:, None], np.sin(yaws)[:, None]
    px, py = pts[None, :, 0], pts[None, :, 1]
    ux = (c * px - s * py + (xy[0] - fld.origin_xy[0])) / fld.resolution
    uy = (s * px + c * py + (xy[1] - fld.origin_xy[1])) / fld.resolution
    return np.floor(uy).astype(np.int32), np.floor(ux).astype(np.int32)


def _scores(grid: NDArray[np.float32], rows, cols, a, ox, oy) -> NDArray[np.float64]:
    H, W = grid.shape
    r = np.clip(rows[a] + oy[:, None], 0, H - 1)
    c = np.clip(cols[a] + ox[:, None], 0, W - 1)
    return grid[r, c].mean(axis=1, dtype=np.float64)


def correlative_search(
    fld: MatchField,
    pts: NDArray[np.float64],
    center: NDArray[np.float64],
    window_xy_m: float,
    window_yaw_rad: float,
    yaw_step_rad: float,
    min_score: float = 0.0,
) -> SearchResult | None:
    """Exact best pose on the search lattice around ``center`` (branch and bound), or None if < ``min_score``.

    The lattice is ``center + (i·res, j·res, k·yaw_step)`` for ``|i·res| ≤ window_xy_m``,
    ``|k·yaw_step| ≤ window_yaw_rad``.
    """
    pts = np.asarray(pts, np.float64).reshape(-1, 2)
    if len(pts) == 0:
        return None
    res = fld.resolution
    w = int(math.ceil(window_xy_m / res - 1e-9))
    nA = int(math.floor(window_yaw_rad / yaw_step_rad + 1e-9)) if yaw_step_rad > 0 else 0
    yaws = center[2] + np.arange(-nA, nA + 1) * yaw_step_rad
    rows, cols = _rotated_cells(fld, pts, center[:2], yaws)
    A = len(yaws)
    top = 0
    while 2 ** (top + 1) <= w and top < 8:
        top += 1
    fld.ensure_levels(top)
    step = 2**top
    offs = np.arange(-w, w + 1, step)
    a, ox, oy = np.meshgrid(np.arange(A), offs, offs, indexing="ij")
    a, ox, oy = a.ravel(), ox.ravel(), oy.ravel()

    def children(a, ox, oy, h):
        """Candidates of level h-1 inside the window covered by level-h candidates."""
        half = 2 ** (h - 1)
        da = np.array([0, half, 0, half])
        db = np.array([0, 0, half, half])
        ca = np.repeat(a, 4)
        cx = (ox[:, None] + da[None, :]).ravel()
        cy = (oy[:, None] + db[None, :]).ravel()
        keep = (cx <= w) & (cy <= w)
        return ca[keep], cx[keep], cy[keep]

    best_score = -1.0
    best = (0, 0, 0)
    h = top
    while True:
        sc = _scores(fld.pyramid[h], rows, cols, a, ox, oy)
        if h == 0:
            i = int(np.argmax(sc)) if len(sc) else -1
            if i >= 0 and sc[i] > best_score:
                best_score, best = float(sc[i]), (int(a[i]), int(ox[i]), int(oy[i]))
            break
        # greedy dive from the best candidate for an exact lower bound
        if len(sc):
            i = int(np.argmax(sc))
            da, dx, dy = a[i : i + 1], ox[i : i + 1], oy[i : i + 1]
            for hh in range(h, 0, -1):
                da, dx, dy = children(da, dx, dy, hh)
                s2 = _scores(fld.pyramid[hh - 1], rows, cols, da, dx, dy)
                j = int(np.argmax(s2))
                da, dx, dy = da[j : j + 1], dx[j : j + 1], dy[j : j + 1]
                if hh == 1 and s2[j] > best_score:
                    best_score, best = float(s2[j]), (int(da[0]), int(dx[0]), int(dy[0]))
        keep = sc > max(best_score, min_score)
        a, ox, oy = a[keep], ox[keep], oy[keep]
        if len(a) == 0:
            break
        a, ox, oy = children(a, ox, oy, h)
        h -= 1
    if best_score < min_score or best_score < 0:
        return None
    k, i, j = best
    pose = np.array([center[0] + i * res, center[1] + j * res, float(wrap_angle(yaws[k]))])
    return SearchResult(pose=pose, score=best_score)


def score_pose(fld: MatchField, pts: NDArray[np.float64], pose: NDArray[np.float64]) -> float:
    """Mean likelihood of ``pts`` at ``pose`` (nearest cell)."""
    rows, cols = _rotated_cells(fld, pts, pose[:2], np.array([pose[2]]))
    return float(_scores(fld.score, rows, cols, np.zeros(1, int), np.zeros(1, int), np.zeros(1, int))[0])


def refine(
    fld: MatchField,
    pts: NDArray[np.float64],
    init: NDArray[np.float64],
    prior: NDArray[np.float64] | None = None,
    prior_info: NDArray[np.float64] | None = None,
    max_dist_m: float = 0.25,
    robust_m: float = 0.03,
    point_weight: float = 0.1,
    inlier_m: float = 0.05,
    iterations: int = 12,
) -> RefineResult:
    """Gauss–Newton point-to-line refinement of ``init`` (see the module docstring).

    Args:
        prior, prior_info: optional ``(3,)`` prior pose and ``(3,)`` diagonal information (1/σ²).
        max_dist_m: correspondences farther than this from their nearest map point are ignored.
        robust_m: Cauchy kernel scale (m).
        point_weight: weight of the point-to-point term relative to point-to-line, scaled by how far
            the neighbourhood is from a clean line (corners and isolated points pull in 2D).
    """
    pts = np.asarray(pts, np.float64).reshape(-1, 2)
    x = np.asarray(init, np.float64).copy()
    H, W = fld.shape
    px, py = pts[:, 0], pts[:, 1]
    Hs = np.zeros((3, 3))
    it = 0
    for it in range(1, iterations + 1):
        c, s = math.cos(x[2]), math.sin(x[2])
        qx = c * px - s * py + x[0]
        qy = s * px + c * py + x[1]
        col = np.clip(((qx - fld.origin_xy[0]) / fld.resolution).astype(np.int64), 0, W - 1)
        row = np.clip(((qy - fld.origin_xy[1]) / fld.resolution).astype(np.int64), 0, H - 1)
        k = fld.nearest[row, col]
        ok = k >= 0
        k = np.where(ok, k, 0)
        ex = qx - fld.points[k, 0]
        ey = qy - fld.points[k, 1]
        ok &= ex * ex + ey * ey < max_dist_m * max_dist_m
        if ok.sum() < 3:
            break
        nx, ny = fld.normals[k[ok], 0], fld.normals[k[ok], 1]
        lam = point_weight * (1.0 - fld.linearity[k[ok]]) + 1e-3
        ex, ey = ex[ok], ey[ok]
        dqx = -s * px[ok] - c * py[ok]  # d q / d yaw
        dqy = c * px[ok] - s * py[ok]
        # Ω = n nᵀ + λ I ; cost eᵀ Ω e
        en = nx * ex + ny * ey
        rho2 = en * en + lam * (ex * ex + ey * ey)
        wgt = 1.0 / (1.0 + rho2 / (robust_m * robust_m))
        # J = [[1, 0, dqx], [0, 1, dqy]]; JᵀΩJ and JᵀΩe, written out
        Oxx = nx * nx + lam
        Oxy = nx * ny
        Oyy = ny * ny + lam
        # Ω J columns
        a0x, a0y = Oxx, Oxy  # Ω [1,0]
        a1x, a1y = Oxy, Oyy  # Ω [0,1]
        a2x, a2y = Oxx * dqx + Oxy * dqy, Oxy * dqx + Oyy * dqy
        Hs = np.empty((3, 3))
        Hs[0, 0] = np.sum(wgt * a0x)
        Hs[0, 1] = Hs[1, 0] = np.sum(wgt * a0y)
        Hs[1, 1] = np.sum(wgt * a1y)
        Hs[0, 2] = Hs[2, 0] = np.sum(wgt * a2x)
        Hs[1, 2] = Hs[2, 1] = np.sum(wgt * a2y)
        Hs[2, 2] = np.sum(wgt * (dqx * a2x + dqy * a2y))
        Oex, Oey = Oxx * ex + Oxy * ey, Oxy * ex + Oyy * ey
        g = np.array([np.sum(wgt * Oex), np.sum(wgt * Oey), np.sum(wgt * (dqx * Oex + dqy * Oey))])
        Ht = Hs.copy()
        if prior is not None and prior_info is not None:
            d = x - prior
            d[2] = wrap_angle(d[2])
            Ht[np.diag_indices(3)] += prior_info
            g = g + prior_info * d
        try:
            dx = -np.linalg.solve(Ht + 1e-9 * np.eye(3), g)
        except np.linalg.LinAlgError:
            break
        x += dx
        x[2] = wrap_angle(x[2])
        if abs(dx[0]) < 1e-5 and abs(dx[1]) < 1e-5 and abs(dx[2]) < 1e-5:
            break
    # final statistics at x
    c, s = math.cos(x[2]), math.sin(x[2])
    qx = c * px - s * py + x[0]
    qy = s * px + c * py + x[1]
    col = np.clip(((qx - fld.origin_xy[0]) / fld.resolution).astype(np.int64), 0, W - 1)
    row = np.clip(((qy - fld.origin_xy[1]) / fld.resolution).astype(np.int64), 0, H - 1)
    k = fld.nearest[row, col]
    ok = k >= 0
    k = np.where(ok, k, 0)
    ex = qx - fld.points[k, 0]
    ey = qy - fld.points[k, 1]
    en = np.abs(fld.normals[k, 0] * ex + fld.normals[k, 1] * ey)
    d2 = ex * ex + ey * ey
    inl = ok & (d2 < max_dist_m * max_dist_m) & (en < inlier_m)
    frac = float(inl.sum()) / max(len(pts), 1)
    rms = float(np.sqrt(np.mean(en[inl] ** 2))) if inl.any() else float("inf")
    return RefineResult(pose=x, inlier_fraction=frac, rms_m=rms, hessian=Hs, iterations=it)
