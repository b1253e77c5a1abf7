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
    #: (3, 3) information of the point-to-line rows only, each weighted by its map point's linearity:
    #: the directions the map's *surfaces* constrain (a corridor: across, not along). Isolated points
    #: (sparse returns at long range, whose normal is undefined) add nothing.
    hessian_line: NDArray[np.float64] | None = None


def _rotated_cells(fld: MatchField, pts: NDArray[np.float64], xy: NDArray[np.float64], yaws: NDArray[np.float64]):
    """Integer cells ``(A, N)`` rows and cols of the points rotated by each yaw and translated by ``xy``."""
    c, s = np.cos(yaws)[:, None], np.sin(yaws)[:, None]
    px, py = pts[None, :, 0], pts[None, :, 1]
    ux = (c * px - s * py + (xy[0] - fld.origin_xy[0])) / fld.resolution
    uy = (s * px + c * py + (xy[1] - fld.origin_xy[1])) / fld.resolution
    return np.floor(uy).astype(np.int32), np.floor(ux).astype(np.int32)


def _scores(grid: NDArray[np.float32], rows, cols, a, ox, oy) -> NDArray[np.float64]:
    """Mean of ``grid`` over the points of each candidate ``(a, ox, oy)`` (out-of-grid cells: the zero border)."""
    H, W = grid.shape
    r = rows[a] + oy[:, None].astype(np.int32)
    c = cols[a] + ox[:, None].astype(np.int32)
    np.minimum(np.maximum(r, 0, out=r), H - 1, out=r)
    np.minimum(np.maximum(c, 0, out=c), W - 1, out=c)
    r *= W
    r += c
    return grid.reshape(-1)[r].mean(axis=1, dtype=np.float64)


def _search_lattice(fld: MatchField, pts: NDArray[np.float64], center: NDArray[np.float64], window_xy_m: float,
                    window_yaw_rad: float, yaw_step_rad: float):
    """The branch-and-bound lattice around ``center``: ``(res, w, yaws, rows, cols, A, top)`` — cell size,
    half-window in cells, the ``A`` candidate yaws, the rotated points' cells per yaw, and the coarsest
    precomputed level ``top`` (``fld``'s levels are built up to it); None without points."""
    pts = np.asarray(pts, np.float64).reshape(-1, 2)
    if len(pts) == 0:
        return None
    res = fld.resolution
    w = int(math.ceil(window_xy_m / res - 1e-9))
    nA = int(math.floor(window_yaw_rad / yaw_step_rad + 1e-9)) if yaw_step_rad > 0 else 0
    yaws = center[2] + np.arange(-nA, nA + 1) * yaw_step_rad
    rows, cols = _rotated_cells(fld, pts, center[:2], yaws)
    top = 0
    while 2 ** (top + 1) <= w and top < 8:
        top += 1
    fld.ensure_levels(top)
    return res, w, yaws, rows, cols, len(yaws), top


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
    lattice = _search_lattice(fld, pts, center, window_xy_m, window_yaw_rad, yaw_step_rad)
    if lattice is None:
        return None
    res, w, yaws, rows, cols, A, top = lattice
    step = 2**top
    offs = np.arange(-w, w + 1, step)
    ga, gx, gy = np.meshgrid(np.arange(A), offs, offs, indexing="ij")
    a, ox, oy = ga.ravel(), gx.ravel(), gy.ravel()

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


def competitor(
    fld: MatchField,
    pts: NDArray[np.float64],
    center: NDArray[np.float64],
    window_xy_m: float,
    window_yaw_rad: float,
    yaw_step_rad: float,
    best: NDArray[np.float64],
    exclude_m: float,
    min_score: float,
    dives: int = 4,
) -> SearchResult | None:
    """A lattice pose (the same lattice as :func:`correlative_search`) farther than ``exclude_m`` from
    ``best`` whose score reaches ``min_score``, or None: the *local uniqueness* test of a match.

    Branch and bound with the bound ``min_score``; regions entirely inside the exclusion disc are
    pruned. Greedy dives from the ``dives`` best top-level regions usually find a competitor at once
    where there is one (a corridor, a periodic façade); the breadth-first search proves there is none.
    """
    lattice = _search_lattice(fld, pts, center, window_xy_m, window_yaw_rad, yaw_step_rad)
    if lattice is None:
        return None
    res, w, yaws, rows, cols, A, top = lattice
    bi = (best[0] - center[0]) / res
    bj = (best[1] - center[1]) / res
    r = exclude_m / res

    def outside(ox, oy, h):
        """True where some lattice point of the region [ox, ox+2^h) × [oy, oy+2^h) is outside the disc."""
        span = 2**h - 1
        fx = np.maximum(np.abs(ox - bi), np.abs(ox + span - bi))
        fy = np.maximum(np.abs(oy - bj), np.abs(oy + span - bj))
        return fx * fx + fy * fy > r * r

    def children(a, ox, oy, h):
        half = 2 ** (h - 1)
        da = np.array([0, half, 0, half])
        db = np.array([0, 0, half, half])
        ca = np.repeat(a, 4)
        cx = (ox[:, None] + da[None, :]).ravel()
        cy = (oy[:, None] + db[None, :]).ravel()
        keep = (cx <= w) & (cy <= w) & outside(cx, cy, h - 1)
        return ca[keep], cx[keep], cy[keep]

    def found(a, ox, oy, sc):
        i = int(np.argmax(sc))
        return SearchResult(np.array([center[0] + ox[i] * res, center[1] + oy[i] * res, float(wrap_angle(yaws[a[i]]))]), float(sc[i]))

    step = 2**top
    offs = np.arange(-w, w + 1, step)
    ga, gx, gy = np.meshgrid(np.arange(A), offs, offs, indexing="ij")
    a, ox, oy = ga.ravel(), gx.ravel(), gy.ravel()
    keep = outside(ox, oy, top)
    a, ox, oy = a[keep], ox[keep], oy[keep]
    h = top
    sc = _scores(fld.pyramid[h], rows, cols, a, ox, oy)
    if h == 0:
        ok = sc >= min_score
        return found(a[ok], ox[ok], oy[ok], sc[ok]) if ok.any() else None
    # greedy dives
    for i in np.argsort(-sc)[:dives]:
        if sc[i] < min_score:
            break
        da, dx, dy = a[i : i + 1], ox[i : i + 1], oy[i : i + 1]
        for hh in range(h, 0, -1):
            da, dx, dy = children(da, dx, dy, hh)
            if len(da) == 0:
                break
            s2 = _scores(fld.pyramid[hh - 1], rows, cols, da, dx, dy)
            j = int(np.argmax(s2))
            if s2[j] < min_score:
                break
            if hh == 1:
                return found(da[j : j + 1], dx[j : j + 1], dy[j : j + 1], s2[j : j + 1])
            da, dx, dy = da[j : j + 1], dx[j : j + 1], dy[j : j + 1]
    # breadth-first, pruned by the bound
    while True:
        keep = sc >= min_score
        a, ox, oy = a[keep], ox[keep], oy[keep]
        if len(a) == 0:
            return None
        a, ox, oy = children(a, ox, oy, h)
        h -= 1
        sc = _scores(fld.pyramid[h], rows, cols, a, ox, oy)
        if h == 0:
            ok = sc >= min_score
            return found(a[ok], ox[ok], oy[ok], sc[ok]) if ok.any() else None


def line_hessian(r: RefineResult) -> NDArray[np.float64]:
    """``(3, 3)`` information of the point-to-line rows of a refinement (the full Hessian if it has none)."""
    return r.hessian_line if r.hessian_line is not None else r.hessian


def _solve3(A: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """``-(A + 1e-9 I)⁻¹ b`` for a symmetric ``(3, 3)`` ``A`` (Cramer's rule; ``np.linalg.solve`` costs
    ten times more for one 3×3 system), or None if it is singular."""
    a, b_, c = float(A[0, 0]) + 1e-9, float(A[0, 1]), float(A[0, 2])
    d, e, f = float(A[1, 1]) + 1e-9, float(A[1, 2]), float(A[2, 2]) + 1e-9
    # cofactors of the symmetric matrix [[a, b, c], [b, d, e], [c, e, f]]
    c00, c01, c02 = d * f - e * e, c * e - b_ * f, b_ * e - c * d
    det = a * c00 + b_ * c01 + c * c02
    if not math.isfinite(det) or abs(det) < 1e-300:
        return None
    c11, c12, c22 = a * f - c * c, b_ * c - a * e, a * d - b_ * b_
    g0, g1, g2 = float(b[0]), float(b[1]), float(b[2])
    s = -1.0 / det
    return np.array([
        s * (c00 * g0 + c01 * g1 + c02 * g2),
        s * (c01 * g0 + c11 * g1 + c12 * g2),
        s * (c02 * g0 + c12 * g1 + c22 * g2),
    ])


def score_pose(fld: MatchField, pts: NDArray[np.float64], pose: NDArray[np.float64]) -> float:
    """Mean likelihood of ``pts`` at ``pose`` (nearest cell)."""
    rows, cols = _rotated_cells(fld, pts, pose[:2], np.array([pose[2]]))
    return float(_scores(fld.score, rows, cols, np.zeros(1, int), np.zeros(1, int), np.zeros(1, int))[0])


def _associate(fld: MatchField, pts: NDArray[np.float64], x: NDArray[np.float64], max_d2: float):
    """Points ``q`` (N, 2) at pose ``x``, nearest map point index ``k`` (N,), ``e = q − p_k`` (N, 2), valid mask."""
    c, s = math.cos(x[2]), math.sin(x[2])
    q = pts @ np.array([[c, s], [-s, c]]) + x[:2]
    H, W = fld.shape
    u = ((q - fld.origin_xy) * (1.0 / fld.resolution)).astype(np.int64)
    col = np.minimum(np.maximum(u[:, 0], 0), W - 1)
    row = np.minimum(np.maximum(u[:, 1], 0), H - 1)
    k = fld.nearest.reshape(-1)[row * W + col]
    ok = k >= 0
    k = np.where(ok, k, 0)
    e = q - fld.points[k]
    ok &= np.einsum("ij,ij->i", e, e) < max_d2
    return q, k, e, ok


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
    Hs = np.zeros((3, 3))
    Hl = np.zeros((3, 3))
    it = 0
    if prior is not None and prior_info is not None:
        prior = np.asarray(prior, np.float64)
        prior_info = np.asarray(prior_info, np.float64)
    md2 = max_dist_m * max_dist_m
    r2 = robust_m * robust_m
    for it in range(1, iterations + 1):  # noqa: B007 (the count is returned)
        q, k, e, ok = _associate(fld, pts, x, md2)
        sel = np.flatnonzero(ok)
        if len(sel) < 3:
            break
        ks, es = k[sel], e[sel]
        n = fld.normals[ks]
        lin = fld.linearity[ks]
        lam = point_weight * (1.0 - lin) + 1e-3
        c, s_ = math.cos(x[2]), math.sin(x[2])
        p = pts[sel]
        dqx = -s_ * p[:, 0] - c * p[:, 1]  # d q / d yaw
        dqy = c * p[:, 0] - s_ * p[:, 1]
        ex, ey = es[:, 0], es[:, 1]
        en = n[:, 0] * ex + n[:, 1] * ey
        wgt = 1.0 / (1.0 + (en * en + lam * (ex * ex + ey * ey)) / r2)  # Cauchy
        # Normal equations of the weighted rows: point-to-line  j = (n_x, n_y, n·dq), r = n·e, and
        # point-to-point  √λ·(1, 0, dq_x), √λ·e_x  and  √λ·(0, 1, dq_y), √λ·e_y  (closed form, no (3m, 3) J)
        nd = n[:, 0] * dqx + n[:, 1] * dqy
        J1 = np.stack([n[:, 0], n[:, 1], nd], axis=1)  # (m, 3)
        wl = wgt * lam
        Hs = (J1 * wgt[:, None]).T @ J1
        sw = wl.sum()
        sx_q, sy_q, sqq = wl @ dqx, wl @ dqy, wl @ (dqx * dqx + dqy * dqy)
        Hs[0, 0] += sw
        Hs[1, 1] += sw
        Hs[0, 2] += sx_q
        Hs[2, 0] += sx_q
        Hs[1, 2] += sy_q
        Hs[2, 1] += sy_q
        Hs[2, 2] += sqq
        Jl = J1 * np.sqrt(wgt * lin)[:, None]
        Hl = Jl.T @ Jl
        we = wgt * en
        g = J1.T @ we + np.array([wl @ ex, wl @ ey, wl @ (dqx * ex + dqy * ey)])
        Ht = Hs.copy()
        if prior is not None and prior_info is not None:
            d = x - prior
            d[2] = (d[2] + math.pi) % (2 * math.pi) - math.pi
            Ht[0, 0] += prior_info[0]
            Ht[1, 1] += prior_info[1]
            Ht[2, 2] += prior_info[2]
            g = g + prior_info * d
        dx = _solve3(Ht, g)
        if dx is None:
            break
        x += dx
        x[2] = (x[2] + math.pi) % (2 * math.pi) - math.pi
        if abs(dx[0]) < 1e-4 and abs(dx[1]) < 1e-4 and abs(dx[2]) < 1e-4:
            break
    # final statistics at x
    q, k, e, ok = _associate(fld, pts, x, md2)
    en = np.abs(np.einsum("ij,ij->i", fld.normals[k], e))
    inl = ok & (en < inlier_m)
    frac = float(inl.sum()) / max(len(pts), 1)
    rms = float(np.sqrt(np.mean(en[inl] ** 2))) if inl.any() else float("inf")
    return RefineResult(pose=x, inlier_fraction=frac, rms_m=rms, hessian=Hs, iterations=it, hessian_line=Hl)
