"""Perturbed versions of a CARMEN log, for the robustness suite (a log *as another robot would give it*).

Each function returns a new :class:`~app.ocslam.slam.carmen.CarmenLog`; the original is not modified.

- :func:`drop_scans`: keep every ``k``-th scan (half the scan rate: twice the motion between scans).
- :func:`resample_beams`: a 1° scan resampled to 0.5° (361 beams over the 180° field, CARMEN's layout):
  the new in-between beams are interpolated where both neighbours see the same surface (ranges within
  ``edge_m`` + 5 %), else they are *no return* (a depth edge is not a wall); beams past the original
  field are no return.
- :func:`add_range_noise`: Gaussian noise on every return (no-return beams stay no return).
- :func:`start_at`: the log from a fraction of its duration on (the map starts mid-building, with
  whatever odometry the robot had then).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from app.ocslam.slam.carmen import CarmenLog, beam_layout


def _subset(log: CarmenLog, idx: np.ndarray, name: str) -> CarmenLog:
    inf = dict(log.inferred or {})
    inf["perturbation"] = (inf.get("perturbation", "") + " " + name).strip()
    inf["scans"] = int(len(idx))
    return dataclasses.replace(
        log,
        stamps=log.stamps[idx].copy(),
        ranges=[log.ranges[i] for i in idx],
        odom=log.odom[idx].copy(),
        flaser_odom=log.flaser_odom[idx].copy(),
        stamp_strings=[log.stamp_strings[i] for i in idx],
        flaser_laser=None if log.flaser_laser is None else log.flaser_laser[idx].copy(),
        inferred=inf,
    )


def drop_scans(log: CarmenLog, keep_every: int = 2) -> CarmenLog:
    """Every ``keep_every``-th scan (the first kept)."""
    return _subset(log, np.arange(0, len(log), max(1, int(keep_every))), f"drop(keep 1/{keep_every})")


def start_at(log: CarmenLog, fraction: float = 0.5) -> CarmenLog:
    """The scans from ``fraction`` of the log's duration on."""
    t = log.stamps[0] + fraction * (log.stamps.max() - log.stamps[0])
    first = int(np.argmax(log.stamps >= t))
    return _subset(log, np.arange(first, len(log)), f"start({fraction:.2f})")


def add_range_noise(log: CarmenLog, sigma_m: float = 0.02, seed: int = 0) -> CarmenLog:
    """Gaussian range noise ``sigma_m`` on every finite return."""
    rng = np.random.default_rng(seed)
    out = []
    for r in log.ranges:
        r = r.copy()
        f = np.isfinite(r)
        r[f] = np.maximum(r[f] + rng.normal(0.0, sigma_m, int(f.sum())), 0.0)
        out.append(r)
    inf = dict(log.inferred or {})
    inf["perturbation"] = (inf.get("perturbation", "") + f" noise({sigma_m:g} m)").strip()
    return dataclasses.replace(log, ranges=out, inferred=inf)


def resample_ranges(r: np.ndarray, factor: int = 2, edge_m: float = 0.1) -> np.ndarray:
    """``(n,)`` ranges at increment ``Δ`` → ``(factor·(n−1)+1 + pad,)`` at ``Δ/factor`` (see the module docstring).

    The output covers the same first beam; for 180 beams at 1° and ``factor`` 2 it has 361 beams over
    [−90°, +90°], the last two (past the original +89°) without return.
    """
    r = np.asarray(r, np.float64)
    n = len(r)
    m = factor * (n - 1) + 1
    out = np.full(m, np.inf)
    out[::factor] = r
    a, b = r[:-1], r[1:]
    with np.errstate(invalid="ignore"):
        same = np.isfinite(a) & np.isfinite(b) & (np.abs(a - b) <= edge_m + 0.05 * np.minimum(a, b))
    for k in range(1, factor):
        f = k / factor
        out[k::factor] = np.where(same, (1 - f) * a + f * b, np.inf)
    # pad to the layout CARMEN uses for the new count (180 → 361 at 0.5°)
    want = {359: 361, 179 * 4 + 1: 721}.get(m, m)
    if want > m:
        out = np.concatenate([out, np.full(want - m, np.inf)])
    return out


def resample_beams(log: CarmenLog, factor: int = 2, edge_m: float = 0.1) -> CarmenLog:
    """Every scan resampled to ``1/factor`` of its angular increment (:func:`resample_ranges`)."""
    out = [resample_ranges(r, factor, edge_m) for r in log.ranges]
    inf = dict(log.inferred or {})
    inf["perturbation"] = (inf.get("perturbation", "") + f" resample(x{factor})").strip()
    n = len(out[0]) if out else 0
    if n:
        amin, inc = beam_layout(n)
        inf.update(beams=n, beam_counts=[n], angle_increment_deg=math.degrees(inc), fov_deg=math.degrees(inc * (n - 1)))
    return dataclasses.replace(log, ranges=out, inferred=inf)


PERTURBATIONS = {
    "drop": lambda log: drop_scans(log, 2),
    "resample": lambda log: resample_beams(log, 2),
    "noise": lambda log: add_range_noise(log, 0.02, 0),
    "mid": lambda log: start_at(log, 0.5),
}


__all__ = ["drop_scans", "start_at", "add_range_noise", "resample_ranges", "resample_beams", "PERTURBATIONS"]
