"""Loop-closure verification: a closure bends the map only once it is confirmed.

Three checks, in the order a candidate meets them (:class:`LoopVerifier`):

1. **Single-cluster (pairwise) consistency, delayed acceptance.** A candidate ``(a → k, z)`` found by the
   matcher is held *pending*. Two candidates ``(a₁ → k₁, z₁)``, ``(a₂ → k₂, z₂)`` are consistent when the
   cycle they close with the current graph is near the identity: the loops place ``k₁`` and ``k₂`` at
   ``x_a₁ ∘ z₁`` and ``x_a₂ ∘ z₂``; their relative pose must agree with the tracked ``x_k₁⁻¹ ∘ x_k₂``
   (a short stretch of odometry and scan matching) within ``loop_pair_chi2``, under the pair's combined
   precision (:func:`pair_chi2`: a loop loose along a corridor cannot confirm another's position along
   it) plus a term growing with the keyframe distance. A group of ``loop_cluster_min`` mutually consistent
   candidates is accepted together; a candidate consistent with a recently accepted closure joins it
   at once; a candidate still unconfirmed ``loop_confirm_keyframes`` keyframes later is rejected
   (``unconfirmed``).
   A group whose correction is *large* (more than ``loop_big_correction_m`` / ``_rad``) must also
   involve at least two submaps (two anchors): one corner of a building can look like another, two
   stretches of an old path rarely do at the same offset. Until then it waits (and may expire).
2. **Odometry over the loop.** Before a group is accepted, the correction it asks for,
   ``e = (x_a⁻¹ ∘ x_k)⁻¹ ∘ z``, is compared with what the graph allows:
   ``χ² = eᵀ (Σ_graph + Σ_z)⁻¹ e`` where ``Σ_graph`` is the covariance of ``k`` relative to ``a`` from
   the graph's information (:func:`~app.ocslam.slam.graph.relative_covariance`). A group beyond
   ``loop_gate_chi2`` is rejected (``odometry``): a place that only *looks* like an old one, far from
   where the drift can have taken the robot.
3. **After every optimisation** (:meth:`app.ocslam.slam.mapper.Slam.optimize`): a loop edge whose χ²
   is still above ``loop_residual_chi2`` (its Cauchy weight near zero: the rest of the graph disagrees)
   is removed and the graph re-optimised (``residual``). So a wrong closure does not survive the next
   optimisation once other evidence contradicts it.

Rejected closures are kept (``rejected``: ``(anchor, keyframe, reason)``) for display and counted by
reason (``rejected_by``).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from app.ocslam.config import SlamConfig
from app.ocslam.se2 import between, compose, wrap_angle
from app.ocslam.slam.graph import relative_covariance


@dataclass
class Candidate:
    """A loop closure found by the matcher: edge ``anchor → keyframe`` measuring ``z`` ``(3,)`` with ``info`` ``(3, 3)``."""

    anchor: int
    keyframe: int
    z: NDArray[np.float64]
    info: NDArray[np.float64]
    score: float = 0.0


def _safe_inv(info: NDArray[np.float64]) -> NDArray[np.float64]:
    try:
        return np.asarray(np.linalg.inv(info + 1e-12 * np.eye(3)), np.float64)
    except np.linalg.LinAlgError:
        return np.eye(3) * 1e6


def _chi2(e: NDArray[np.float64], cov: NDArray[np.float64]) -> float:
    cov = 0.5 * (cov + cov.T)
    try:
        return float(e @ np.linalg.solve(cov, e))
    except np.linalg.LinAlgError:
        return float("inf")


def cycle_error(poses: NDArray[np.float64], c1: Candidate, c2: Candidate) -> NDArray[np.float64]:
    """``(3,)`` error of the cycle closed by two loop candidates with the current poses, in ``k₂``'s frame."""
    L1 = compose(poses[c1.anchor], c1.z)
    L2 = compose(poses[c2.anchor], c2.z)
    d_loop = between(L1, L2)
    d_track = between(poses[c1.keyframe], poses[c2.keyframe])
    e = between(d_track, d_loop)
    e[2] = wrap_angle(e[2])
    return e


def pair_chi2(poses: NDArray[np.float64], c1: Candidate, c2: Candidate, sigma_per_kf_xy: float = 0.01, sigma_per_kf_yaw: float = 0.002) -> float:
    """χ² of :func:`cycle_error` under the pair's *combined* precision plus a keyframe-distance term.

    The covariance is ``2 (Ω₁ + Ω₂)⁻¹``: in a direction where either candidate is firm the pair must
    agree to that precision, so a candidate that is loose along a corridor (its information stripped
    there) cannot vouch for another's position along it; two loose ones agree trivially there, and
    carry no information there either.
    """
    e = cycle_error(poses, c1, c2)
    n = abs(c1.keyframe - c2.keyframe) + abs(c1.anchor - c2.anchor)
    track = np.diag([(sigma_per_kf_xy * n) ** 2, (sigma_per_kf_xy * n) ** 2, (sigma_per_kf_yaw * n) ** 2])
    cov = 2.0 * _safe_inv(c1.info + c2.info) + track + np.diag([1e-6, 1e-6, 1e-8])
    return _chi2(e, cov)


def loop_correction(poses: NDArray[np.float64], c: Candidate) -> NDArray[np.float64]:
    """``(3,)`` correction ``(x_a⁻¹ ∘ x_k)⁻¹ ∘ z`` a candidate asks for (in ``k``'s frame)."""
    e = between(between(poses[c.anchor], poses[c.keyframe]), c.z)
    e[2] = wrap_angle(e[2])
    return e


class LoopVerifier:
    """Pending loop candidates and the checks of the module docstring."""

    def __init__(self, cfg: SlamConfig) -> None:
        self.cfg = cfg
        self.pending: list[Candidate] = []
        self.accepted: list[Candidate] = []
        self.rejected: list[tuple[int, int, str]] = []
        self.rejected_by: Counter[str] = Counter()
        self.gate_chi2: list[float] = []  # χ² of every group that met the odometry gate (diagnostics)
        self.held = 0  # times a large-correction group waited for a second submap

    def reject(self, c: Candidate, reason: str) -> None:
        self.rejected.append((int(c.anchor), int(c.keyframe), reason))
        self.rejected_by[reason] += 1

    def expire(self, k: int) -> None:
        """Reject pending candidates older than ``loop_confirm_keyframes`` keyframes at keyframe ``k``."""
        keep = []
        for c in self.pending:
            if k - c.keyframe > self.cfg.loop_confirm_keyframes:
                self.reject(c, "unconfirmed")
            else:
                keep.append(c)
        self.pending = keep

    def gate(self, poses, ij, z, info, c: Candidate) -> float:
        """χ² of ``c``'s correction against the graph's covariance of ``k`` relative to ``a`` (+ ``c``'s own)."""
        cov = relative_covariance(poses, ij, z, info, c.anchor, c.keyframe) + _safe_inv(c.info)
        return _chi2(loop_correction(poses, c), cov)

    def offer(self, c: Candidate, poses, ij, z, info) -> list[Candidate]:
        """Add a candidate; returns the candidates accepted now (possibly earlier pending ones too).

        ``poses`` ``(K, 3)`` and the active edges ``ij``, ``z``, ``info`` describe the current graph.
        """
        cfg = self.cfg
        self.expire(c.keyframe)
        recent = [a for a in self.accepted[-50:] if c.keyframe - a.keyframe <= cfg.loop_confirm_keyframes]
        if any(pair_chi2(poses, a, c) <= cfg.loop_pair_chi2 for a in recent):
            self.accepted.append(c)
            return [c]
        group = [p for p in self.pending if pair_chi2(poses, p, c) <= cfg.loop_pair_chi2]
        if len(group) + 1 < cfg.loop_cluster_min:
            self.pending.append(c)
            return []
        group.append(c)
        best = max(group, key=lambda g: float(np.linalg.eigvalsh(g.info[:2, :2])[0]))
        corr = loop_correction(poses, best)
        big = math.hypot(corr[0], corr[1]) > cfg.loop_big_correction_m or abs(corr[2]) > cfg.loop_big_correction_rad
        if big and len({g.anchor for g in group}) < 2:
            # a large jump seen against one submap only (one corner can look like another): wait for a
            # second submap to agree before bending the map
            self.pending.append(c)
            self.held += 1
            return []
        chi2 = self.gate(poses, ij, z, info, best)
        self.gate_chi2.append(chi2)
        ids = {id(g) for g in group}
        self.pending = [p for p in self.pending if id(p) not in ids]
        if chi2 > cfg.loop_gate_chi2:
            for g in group:
                self.reject(g, "odometry")
            return []
        self.accepted.extend(group)
        return group

    @property
    def rejected_count(self) -> int:
        return int(sum(self.rejected_by.values()))


__all__ = ["Candidate", "LoopVerifier", "cycle_error", "pair_chi2", "loop_correction"]
