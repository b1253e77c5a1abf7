"""Whether a footprint's unseen part can be where it was completed (principle 20, improved mode).

A footprint completed beyond its LIDAR points (to its class's depth, to its boxes' apparent width) hides
that part from the robot behind the object's own face. When the occupancy grid knows an obstacle on the
lines of sight to that part, past the object's front and away from its points (a wall behind a shelf),
the completion is impossible (:func:`unseen_part_conflict`;
:func:`app.ocslam.footprint_estimate.estimate_footprint` then turns the object the other way round).
All in the object frame (``map``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from app.ocslam.footprint import linspace, nearest_distances

__all__ = ["unseen_part_conflict", "view_indices"]

FloatArray = NDArray[np.float64]
OccupiedFn = Callable[[FloatArray], NDArray[np.bool_]]

#: samples of a footprint this close to the rectangle of its points are the points' own (m)
_OWN_M = 0.1
#: steps along a line of sight (m)
_STEP_M = 0.05


def view_indices(m: int) -> list[int]:
    """Up to three of ``m`` viewpoints: the first, the middle one and the last (``np.linspace(0, m − 1, 3)``
    rounded, without repeats)."""
    return list(range(m)) if m <= 3 else [0, round((m - 1) / 2), m - 1]


def unseen_part_conflict(
    occupied: OccupiedFn, views: FloatArray, pts: FloatArray, axes: FloatArray, lo: FloatArray, hi: FloatArray,
    s_center: FloatArray, size: FloatArray,
) -> float:
    """The share of a footprint's extrapolated part that every viewpoint sees only through an obstacle that
    is not the object (a wall behind it).

    ``occupied``: ``(N, 2)`` points → True where the map knows an obstacle; ``views`` ``(V, 2)`` the
    viewpoints; ``pts`` ``(N, 2)`` the object's points; ``axes`` ``(2, 2)`` the rectangle's axes (rows),
    ``lo``, ``hi`` its points' extent and ``s_center``, ``size`` the footprint, in rectangle coordinates.
    A 5 × 5 grid of the footprint's samples farther than 0.1 m from the points' rectangle is the
    extrapolated part; a sample is hidden behind something else when the line of sight from each of (up
    to three of) the viewpoints passes a known obstacle beyond the object's nearest point, farther than
    0.1 m from every point of the object and short of the sample by 0.1 m. 0 when fewer than 3 samples are extrapolated.
    """
    if len(views) == 0 or len(pts) == 0:
        return 0.0
    a = linspace(float(s_center[0] - size[0] / 2 + 0.05), float(s_center[0] + size[0] / 2 - 0.05), 5)
    b = linspace(float(s_center[1] - size[1] / 2 + 0.05), float(s_center[1] + size[1] / 2 - 0.05), 5)
    samples = np.empty((5, 5, 2))  # the 5 × 5 samples, b-major (rows of ``a``)
    samples[:, :, 0] = a[None, :]
    samples[:, :, 1] = b[:, None]
    S = samples.reshape(25, 2)
    out = ((S[:, 0] < lo[0] - _OWN_M) | (S[:, 0] > hi[0] + _OWN_M)
           | (S[:, 1] < lo[1] - _OWN_M) | (S[:, 1] > hi[1] + _OWN_M))
    if int(np.count_nonzero(out)) < 3:
        return 0.0
    P = S[out] @ axes  # rectangle coordinates → object frame
    V = views[view_indices(len(views))]
    hidden = np.ones(len(P), dtype=bool)
    for v in V:
        d = P - v[None, :]
        r = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1])
        n = int(np.ceil(float(r.max()) / _STEP_M))
        if n < 3:
            return 0.0
        t = np.arange(1, n + 1) * _STEP_M  # (n,) distance from the viewpoint
        Q = v[None, None, :] + t[None, :, None] * (d / np.maximum(r, 1e-9)[:, None])[:, None, :]  # (P, n, 2)
        dp = pts - v[None, :]
        front = float(np.sqrt((dp[:, 0] * dp[:, 0] + dp[:, 1] * dp[:, 1]).min()))
        # on the line of sight past the object's nearest point, short of the sample: what stands in front of
        # the object (hiding part of it) says nothing of its depth
        before = (t[None, :] > front) & (t[None, :] < (r[:, None] - _OWN_M))
        occ = np.zeros((len(P), n), dtype=bool)
        if before.any():
            occ[before] = occupied(Q[before])  # only the samples that count are looked up
        if occ.any():
            hit = Q[occ]
            occ[occ] = nearest_distances(hit, pts) > _OWN_M  # an obstacle that is not the object itself
        hidden &= occ.any(axis=1)
        if not hidden.any():
            return 0.0
    return float(np.count_nonzero(hidden)) / len(P)
