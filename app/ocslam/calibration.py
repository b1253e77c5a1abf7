"""Score calibration: a detector's box score as the probability that the box is right.

The soft decision (paper §2.5.4) compares ``Y_c · f/F`` with the presence threshold (80 %), so it reads
the box score as a probability. A network's score is not one: two trainings of the same network on
similar data put the same true boxes at different scores (detector v3 scored the apartment's objects at
0.8–0.95, v4 at 0.6–0.85 with *higher* precision), and the threshold silently means something else
with every model. Platt scaling (Platt 1999; Guo et al. 2017) maps the score to the probability that
a box of that score matches a true object (IoU ≥ 0.5, same class), fitted on labelled renders of
worlds the network never saw:

    p = σ(a · logit(s) + b)

Monotone in ``s`` for ``a > 0``, so it keeps every ranking (which box is kept, which object wins a
collision) and changes only what a score *means*. The identity is ``a = 1, b = 0``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

_EPS = 1e-6


def _logit(s: FloatArray) -> FloatArray:
    s = np.clip(s, _EPS, 1.0 - _EPS)
    return np.log(s) - np.log1p(-s)


@dataclass(frozen=True, slots=True)
class ScoreCalibration:
    """``p = σ(slope · logit(score) + offset)`` (Platt scaling); the default is the identity."""

    slope: float = 1.0
    offset: float = 0.0

    @property
    def is_identity(self) -> bool:
        return self.slope == 1.0 and self.offset == 0.0

    def probability(self, score: float) -> float:
        """The calibrated probability of one score in ``[0, 1]`` (the identity returns it unchanged)."""
        if self.is_identity:
            return float(score)
        return float(self.probabilities(np.array([score], dtype=np.float64))[0])

    def probabilities(self, scores: ArrayLike) -> FloatArray:
        """``(N,)`` calibrated probabilities of ``(N,)`` scores."""
        s = np.asarray(scores, dtype=np.float64)
        if self.is_identity:
            return s.copy()
        z = self.slope * _logit(s) + self.offset
        return 1.0 / (1.0 + np.exp(-z))

    def to_dict(self) -> dict[str, float]:
        return {"slope": float(self.slope), "offset": float(self.offset)}

    @classmethod
    def from_dict(cls, d: Any) -> ScoreCalibration:
        """From a model card's ``score_calibration`` entry; raises ``ValueError`` on a malformed one
        (a slope that is not positive would reverse the ranking of boxes)."""
        if not isinstance(d, dict):
            raise ValueError(f"score_calibration must be a mapping, got {type(d).__name__}")
        try:
            slope, offset = float(d["slope"]), float(d["offset"])
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(f"score_calibration needs numeric slope and offset ({e})") from None
        if not (math.isfinite(slope) and math.isfinite(offset) and slope > 0.0):
            raise ValueError(f"score_calibration slope must be finite and > 0, offset finite; got {slope}, {offset}")
        return cls(slope, offset)


def fit_platt(scores: ArrayLike, correct: ArrayLike, prior_weight: float = 1e-3, iterations: int = 50) -> ScoreCalibration:
    """Maximum-likelihood Platt scaling of ``(N,)`` scores against ``(N,)`` booleans (box right or not).

    Newton's method on the logistic log-likelihood in ``(a, b)`` over ``logit(score)``, with a weak
    Gaussian prior (``prior_weight``) pulling towards the identity so that separable or tiny samples
    stay finite. Raises ``ValueError`` with fewer than 2 boxes of each kind."""
    x = _logit(np.asarray(scores, dtype=np.float64).reshape(-1))
    y = np.asarray(correct, dtype=bool).reshape(-1).astype(np.float64)
    if x.shape != y.shape:
        raise ValueError(f"scores and labels differ in length ({len(x)} vs {len(y)})")
    n_pos, n_neg = int(y.sum()), int(len(y) - y.sum())
    if n_pos < 2 or n_neg < 2:
        raise ValueError(f"calibration needs at least 2 right and 2 wrong boxes, got {n_pos} and {n_neg}")
    X = np.stack([x, np.ones_like(x)], axis=1)
    theta = np.array([1.0, 0.0])
    lam = float(prior_weight) * len(x)
    for _ in range(iterations):
        p = 1.0 / (1.0 + np.exp(-(X @ theta)))
        grad = X.T @ (p - y) + lam * (theta - np.array([1.0, 0.0]))
        H = (X * (p * (1.0 - p))[:, None]).T @ X + lam * np.eye(2)
        step = np.linalg.solve(H, grad)
        theta = theta - step
        if float(np.max(np.abs(step))) < 1e-10:
            break
    return ScoreCalibration(float(theta[0]), float(theta[1]))


def reliability(probabilities: ArrayLike, correct: ArrayLike, bins: int = 10) -> list[dict[str, float]]:
    """Reliability table: per equal-width probability bin, its boxes, mean probability and share right
    (empty bins left out)."""
    p = np.asarray(probabilities, dtype=np.float64).reshape(-1)
    y = np.asarray(correct, dtype=bool).reshape(-1)
    idx = np.minimum((p * bins).astype(int), bins - 1)
    rows = []
    for k in range(bins):
        m = idx == k
        if np.any(m):
            rows.append({"lo": k / bins, "hi": (k + 1) / bins, "boxes": int(m.sum()),
                         "mean_probability": float(p[m].mean()), "share_right": float(y[m].mean())})
    return rows


def expected_calibration_error(probabilities: ArrayLike, correct: ArrayLike, bins: int = 10) -> float:
    """ECE: the box-weighted mean gap between mean probability and share right over the bins."""
    rows = reliability(probabilities, correct, bins)
    n = sum(r["boxes"] for r in rows)
    if n == 0:
        return 0.0
    return float(sum(r["boxes"] * abs(r["mean_probability"] - r["share_right"]) for r in rows) / n)
