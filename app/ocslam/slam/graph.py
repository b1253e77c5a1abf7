"""The keyframe pose graph and its optimiser (sparse Levenberg–Marquardt with robust loop edges).

Nodes are keyframe poses ``T_map_kf`` ``(K, 3)``. An edge ``(i, j)`` carries a measured relative motion
``z ≈ T_map_i⁻¹ ∘ T_map_j`` and an information matrix: ``(3,)`` diagonal ``(1/σx², 1/σy², 1/σθ²)`` or a
full ``(3, 3)`` one (the scan matcher's, expressed in the frame of ``z``'s end, i.e. node ``j``'s body
frame, so an edge along a corridor constrains across it and not along it). Its error is
``e = z⁻¹ ∘ (x_i⁻¹ ∘ x_j)`` (the standard SE(2) formulation of Grisetti et al., "A tutorial on graph-based
SLAM", 2010). Loop-closure edges get a Cauchy kernel (iteratively reweighted), so a wrong loop that passed
the matcher's acceptance test is down-weighted instead of bending the map. The normal equations are
assembled as a scipy.sparse matrix and factored with SuperLU in its symmetric mode (minimum-degree
ordering of ``A + Aᵀ``, diagonal pivots: the damped normal equations are positive definite), ten times
faster than ``spsolve``'s general LU on a few-thousand-node graph; the first node is held fixed (the map
frame).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

from app.ocslam.se2 import between, wrap_angle


def factor_spd(H: sp.spmatrix) -> spla.SuperLU:
    """SuperLU factorisation of a sparse symmetric positive definite ``H`` (raises RuntimeError if it is
    singular)."""
    return spla.splu(sp.csc_matrix(H), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})


@dataclass
class PoseGraph:
    """A read-only view of the graph for display: nodes ``(K, 3)`` ``T_map_kf``, stamps ``(K,)``,
    edges ``(M, 2)`` node indices, ``is_loop`` ``(M,)`` True for (accepted) loop closures; ``rejected``
    ``(R, 2)`` the loop closures that were found but rejected by verification (not in the optimisation)."""

    nodes: NDArray[np.float64]
    stamps: NDArray[np.float64]
    edges: NDArray[np.int64]
    is_loop: NDArray[np.bool_]
    rejected: NDArray[np.int64] = field(default_factory=lambda: np.zeros((0, 2), np.int64))


@dataclass
class OptimizeResult:
    poses: NDArray[np.float64]  # (K, 3)
    iterations: int
    initial_cost: float
    final_cost: float
    loop_weights: NDArray[np.float64]  # (M,) final robust weight of every edge (1 for non-robust)


def edge_errors(poses: NDArray[np.float64], ij: NDArray[np.int64], z: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(M, 3)`` errors ``z⁻¹ ∘ (x_i⁻¹ ∘ x_j)``."""
    return between(z, between(poses[ij[:, 0]], poses[ij[:, 1]]))


def as_full_info(info: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(M, 3)`` diagonal or ``(M, 3, 3)`` information → ``(M, 3, 3)``."""
    info = np.asarray(info, np.float64)
    if info.ndim == 3:
        return info.reshape(-1, 3, 3)
    info = info.reshape(-1, 3)
    out = np.zeros((len(info), 3, 3))
    out[:, [0, 1, 2], [0, 1, 2]] = info
    return out


def edge_chi2(e: NDArray[np.float64], info: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(M,)`` whitened squared errors ``eᵀ Ω e`` of ``(M, 3)`` errors with ``(M, 3, 3)`` information."""
    return np.einsum("mi,mij,mj->m", e, info, e)


def _cost_and_weights(e, info, robust, scale):
    chi2 = edge_chi2(e, info)
    w = np.ones(len(e))
    cost = chi2.copy()
    if robust.any():
        c2 = scale * scale
        w[robust] = 1.0 / (1.0 + chi2[robust] / c2)
        cost[robust] = c2 * np.log1p(chi2[robust] / c2)
    return float(cost.sum()), w


def linearize(
    x: NDArray[np.float64], ij: NDArray[np.int64], z: NDArray[np.float64], info: NDArray[np.float64],
    w: NDArray[np.float64], e: NDArray[np.float64],
) -> tuple[sp.csc_matrix, NDArray[np.float64]]:
    """Gauss–Newton system at poses ``x`` ``(K, 3)``: sparse ``(3K, 3K)`` ``H = Σ Jᵀ w Ω J`` and ``(3K,)`` ``b = Σ Jᵀ w Ω e``.

    ``info`` ``(M, 3, 3)``, ``w`` ``(M,)`` robust weights, ``e`` ``(M, 3)`` the errors at ``x``.
    """
    K = len(x)
    i, j = ij[:, 0], ij[:, 1]
    blocks_r = np.stack([i, i, j, j], axis=1)  # (M, 4): ii, ij, ji, jj
    blocks_c = np.stack([i, j, i, j], axis=1)
    rr = (blocks_r[:, :, None, None] * 3 + np.arange(3)[None, None, :, None]).repeat(3, axis=3)
    cc = (blocks_c[:, :, None, None] * 3 + np.arange(3)[None, None, None, :]).repeat(3, axis=2)
    rr, cc = rr.ravel(), cc.ravel()
    ti, tj = x[i, :2], x[j, :2]
    thi = x[i, 2]
    ci, si = np.cos(thi), np.sin(thi)
    cz, sz = np.cos(z[:, 2]), np.sin(z[:, 2])
    # R_z^T R_i^T = R(-(θi+θz))
    a = -(thi + z[:, 2])
    ca, sa = np.cos(a), np.sin(a)
    Rzi = np.stack([np.stack([ca, -sa], -1), np.stack([sa, ca], -1)], -2)  # (M, 2, 2)
    dt = tj - ti
    # d(R_i^T)/dθ (t_j - t_i) = [[-s, c], [-c, -s]] dt
    dRt = np.stack([-si * dt[:, 0] + ci * dt[:, 1], -ci * dt[:, 0] - si * dt[:, 1]], -1)
    RzT = np.stack([np.stack([cz, sz], -1), np.stack([-sz, cz], -1)], -2)
    col = np.einsum("mab,mb->ma", RzT, dRt)
    A = np.zeros((len(ij), 3, 3))
    B = np.zeros((len(ij), 3, 3))
    A[:, :2, :2] = -Rzi
    A[:, :2, 2] = col
    A[:, 2, 2] = -1.0
    B[:, :2, :2] = Rzi
    B[:, 2, 2] = 1.0
    Om = info * w[:, None, None]  # (M, 3, 3)
    OA = np.einsum("mkl,mlj->mkj", Om, A)
    OB = np.einsum("mkl,mlj->mkj", Om, B)
    Hii = np.einsum("mki,mkj->mij", A, OA)
    Hij = np.einsum("mki,mkj->mij", A, OB)
    Hjj = np.einsum("mki,mkj->mij", B, OB)
    vals = np.stack([Hii, Hij, np.transpose(Hij, (0, 2, 1)), Hjj], axis=1).ravel()
    Oe = np.einsum("mkl,ml->mk", Om, e)
    bi = np.einsum("mki,mk->mi", A, Oe)
    bj = np.einsum("mki,mk->mi", B, Oe)
    b = np.zeros(3 * K)
    np.add.at(b, (i[:, None] * 3 + np.arange(3)).ravel(), bi.ravel())
    np.add.at(b, (j[:, None] * 3 + np.arange(3)).ravel(), bj.ravel())
    Hm = sp.coo_matrix((vals, (rr, cc)), shape=(3 * K, 3 * K)).tocsc()
    return Hm, b


def optimize(
    poses: NDArray[np.float64],
    ij: NDArray[np.int64],
    z: NDArray[np.float64],
    info: NDArray[np.float64],
    robust: NDArray[np.bool_],
    robust_scale: float = 3.0,
    iterations: int = 20,
    fixed: int = 0,
    tol: float = 1e-6,
    rel_tol: float = 1e-6,
) -> OptimizeResult:
    """Optimise ``(K, 3)`` poses given ``(M, 2)`` edges, ``(M, 3)`` measurements, ``(M, 3)`` diagonal or
    ``(M, 3, 3)`` full information.

    ``robust`` ``(M,)`` selects the edges with a Cauchy kernel of scale ``robust_scale`` (in units of
    the whitened error). Node ``fixed`` does not move. Stops after ``iterations``, when the largest update
    is below ``tol`` or when the cost decreases by less than ``rel_tol`` (relative).
    """
    x = np.array(poses, np.float64, copy=True)
    K = len(x)
    ij = np.asarray(ij, np.int64).reshape(-1, 2)
    z = np.asarray(z, np.float64).reshape(-1, 3)
    info = as_full_info(info)
    robust = np.asarray(robust, bool).reshape(-1)
    if K < 2 or len(ij) == 0:
        return OptimizeResult(x, 0, 0.0, 0.0, np.ones(len(ij)))
    e = edge_errors(x, ij, z)
    cost0, w = _cost_and_weights(e, info, robust, robust_scale)
    cost = cost0
    lam = 1e-4
    it = 0
    for it in range(1, iterations + 1):  # noqa: B007 (the count is returned)
        Hm, b = linearize(x, ij, z, info, w, e)
        keep = np.ones(3 * K, bool)
        keep[3 * fixed : 3 * fixed + 3] = False
        idx = np.flatnonzero(keep)
        Hk = Hm[idx][:, idx]
        diag = Hk.diagonal()
        improved = False
        for _ in range(6):
            Hd = Hk + sp.diags(lam * (diag + 1e-9))
            try:
                dx = factor_spd(Hd).solve(-b[idx])
            except Exception:  # singular system: damp more
                lam *= 10.0
                continue
            if not np.all(np.isfinite(dx)):
                lam *= 10.0
                continue
            xn = x.copy()
            xn.reshape(-1)[idx] += dx
            xn[:, 2] = wrap_angle(xn[:, 2])
            en = edge_errors(xn, ij, z)
            cn, wn = _cost_and_weights(en, info, robust, robust_scale)
            if cn <= cost:
                x, e, w = xn, en, wn
                step = float(np.max(np.abs(dx))) if len(dx) else 0.0
                rel = (cost - cn) / max(cost, 1e-12)
                cost = cn
                lam = max(lam / 10.0, 1e-9)
                improved = True
                break
            lam *= 10.0
        if not improved or step < tol or rel < rel_tol:
            break
    return OptimizeResult(x, it, cost0, cost, w)


def relative_covariance(
    poses: NDArray[np.float64],
    ij: NDArray[np.int64],
    z: NDArray[np.float64],
    info: NDArray[np.float64],
    a: int,
    k: int,
) -> NDArray[np.float64]:
    """``(3, 3)`` covariance of node ``k``'s pose relative to node ``a``, in ``k``'s body frame.

    The graph is linearised at ``poses`` with node ``a`` held fixed; the covariance of ``k``'s map pose is
    the ``k`` block of ``H⁻¹`` (three sparse solves), then rotated into ``k``'s frame (the frame a loop
    edge's error lives in). Nodes not connected to ``a`` get a huge covariance.
    """
    x = np.asarray(poses, np.float64)
    K = len(x)
    ij = np.asarray(ij, np.int64).reshape(-1, 2)
    z = np.asarray(z, np.float64).reshape(-1, 3)
    info = as_full_info(info)
    if K < 2 or len(ij) == 0 or a == k:
        return np.eye(3) * (1e-12 if a == k else 1e12)
    e = edge_errors(x, ij, z)
    Hm, _ = linearize(x, ij, z, info, np.ones(len(ij)), e)
    keep = np.ones(3 * K, bool)
    keep[3 * a : 3 * a + 3] = False
    idx = np.flatnonzero(keep)
    Hk = (Hm[idx][:, idx] + sp.identity(len(idx)) * 1e-9).tocsc()
    col = np.searchsorted(idx, 3 * k)
    rhs = np.zeros((len(idx), 3))
    rhs[col : col + 3] = np.eye(3)
    try:
        X = factor_spd(Hk).solve(rhs)
    except Exception:
        return np.eye(3) * 1e12
    S = X[col : col + 3]
    S = 0.5 * (S + S.T)
    c, s = np.cos(x[k, 2]), np.sin(x[k, 2])
    Gi = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # global → body perturbation
    return Gi @ S @ Gi.T
