"""How closely a replay reproduces the run that was recorded: trajectory and object-map differences."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from app.ocslam.messages import TrackedObject


def trajectory_difference(stamps_a: np.ndarray, poses_a: np.ndarray, stamps_b: np.ndarray, poses_b: np.ndarray,
                          tol_s: float = 1e-6) -> dict[str, float]:
    """Max and RMS position difference (m) and max heading difference (rad) of two ``(N, 3)`` trajectories
    at their common stamps (matched within ``tol_s``)."""
    sa, sb = np.asarray(stamps_a, float), np.asarray(stamps_b, float)
    if not len(sa) or not len(sb):
        return {"matched": 0, "max_m": float("nan"), "rms_m": float("nan"), "max_yaw_rad": float("nan")}
    j = np.clip(np.searchsorted(sb, sa), 0, len(sb) - 1)
    jl = np.clip(j - 1, 0, len(sb) - 1)
    j = np.where(np.abs(sb[jl] - sa) < np.abs(sb[j] - sa), jl, j)
    ok = np.abs(sb[j] - sa) <= tol_s
    a, b = np.asarray(poses_a)[ok], np.asarray(poses_b)[j[ok]]
    d = np.hypot(*(a[:, :2] - b[:, :2]).T)
    dyaw = np.abs(np.remainder(a[:, 2] - b[:, 2] + np.pi, 2 * np.pi) - np.pi)
    return {"matched": int(ok.sum()), "of": len(sa), "max_m": float(d.max()) if len(d) else float("nan"),
            "rms_m": float(np.sqrt(np.mean(d**2))) if len(d) else float("nan"),
            "max_yaw_rad": float(dyaw.max()) if len(dyaw) else float("nan")}


def object_map_difference(a: Sequence[TrackedObject], b: Sequence[TrackedObject], threshold: float,
                          match_m: float = 0.5) -> dict[str, Any]:
    """Objects shown (presence ≥ ``threshold``) in ``a`` and ``b``: matched one-to-one by label and
    nearest centre (Hungarian, within ``match_m``); unmatched counts and the max centre distance."""
    from scipy.optimize import linear_sum_assignment

    sa = [o for o in a if o.presence >= threshold]
    sb = [o for o in b if o.presence >= threshold]
    if not sa or not sb:
        return {"a": len(sa), "b": len(sb), "matched": 0, "only_a": len(sa), "only_b": len(sb), "max_m": 0.0}
    pa = np.array([[o.pose.x, o.pose.y] for o in sa])
    pb = np.array([[o.pose.x, o.pose.y] for o in sb])
    D = np.hypot(pa[:, None, 0] - pb[None, :, 0], pa[:, None, 1] - pb[None, :, 1])
    same = np.array([[oa.label == ob.label for ob in sb] for oa in sa])
    C = np.where(same & (D <= match_m), D, 1e6)
    r, c = linear_sum_assignment(C)
    ok = C[r, c] < 1e6
    d = D[r[ok], c[ok]]
    return {"a": len(sa), "b": len(sb), "matched": int(ok.sum()), "only_a": len(sa) - int(ok.sum()),
            "only_b": len(sb) - int(ok.sum()), "max_m": float(d.max()) if len(d) else 0.0}
