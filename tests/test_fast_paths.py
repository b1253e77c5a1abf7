"""The consciousness' fast paths give the values of the computations they stand for, bit for bit.

Each fast path (issue 14: the consciousness' per-frame cost) rewrote an expression with fewer numpy calls;
the object maps stay identical only if every value does, so each is checked against the plain formulation
it replaced (written out here) on random inputs.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.ocslam.footprint import min_area_rect
from app.ocslam.messages import OccupancyGrid
from app.ocslam.se2 import Pose2
from app.ocslam.unseen_part import view_indices

coord = st.floats(-20.0, 20.0, allow_nan=False, width=64)


def _min_area_rect_reference(points: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """The closeness-criterion rectangle as first written: each axis' projections separately."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    n = len(p)
    if n >= 3:
        q = p - p.mean(axis=0)
        hull = cv2.convexHull(q.astype(np.float32)).reshape(-1, 2).astype(np.float64)
        e = np.roll(hull, -1, axis=0) - hull
        e = e[np.hypot(e[:, 0], e[:, 1]) > 1e-6]
        thetas = np.unique(np.round(np.arctan2(e[:, 1], e[:, 0]) % (np.pi / 2), 9)) if len(e) else np.array([0.0])
        cs, sn = np.cos(thetas)[:, None], np.sin(thetas)[:, None]
        a = q[:, 0][None, :] * cs + q[:, 1][None, :] * sn
        b = q[:, 1][None, :] * cs - q[:, 0][None, :] * sn
        a_lo, a_hi = a.min(axis=1, keepdims=True), a.max(axis=1, keepdims=True)
        b_lo, b_hi = b.min(axis=1, keepdims=True), b.max(axis=1, keepdims=True)
        area = ((a_hi - a_lo) * (b_hi - b_lo))[:, 0]
        if max(np.ptp(q[:, 0]), np.ptp(q[:, 1])) < 0.5:
            th = float(thetas[int(np.argmin(area))])
        else:
            da = np.minimum(a - a_lo, a_hi - a)
            db = np.minimum(b - b_lo, b_hi - b)
            score = (1.0 / np.maximum(np.minimum(da, db), 0.01)).sum(axis=1)
            best = np.flatnonzero(score >= score.max() * (1.0 - 1e-6))
            th = float(thetas[best[np.argmin(area[best])]])
    elif n == 2:
        d = p[1] - p[0]
        th = float(np.arctan2(d[1], d[0]) % (np.pi / 2))
    else:
        th = 0.0
    c, s = np.cos(th), np.sin(th)
    a1 = p[:, 0] * c + p[:, 1] * s
    b1 = -p[:, 0] * s + p[:, 1] * c
    return th, np.array([a1.min(), b1.min()]), np.array([a1.max(), b1.max()])


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 60), st.integers(0, 2**31 - 1), st.sampled_from([0.05, 0.3, 2.0]))
def test_min_area_rect_equals_the_reference(n: int, seed: int, spread: float) -> None:
    rng = np.random.default_rng(seed)
    # an outline (two faces of a rectangle, some noise) or a blob, small or large
    t = rng.uniform(0.0, 1.0, n)
    face = rng.integers(0, 2, n)
    pts = np.where(face[:, None] == 0, np.c_[t * spread, np.zeros(n)], np.c_[np.zeros(n), t * spread * 0.6])
    pts = pts + rng.normal(0.0, 0.01, (n, 2)) + rng.uniform(-5.0, 5.0, 2)
    th, lo, hi = min_area_rect(pts)
    th_r, lo_r, hi_r = _min_area_rect_reference(pts)
    assert th == th_r
    assert np.array_equal(lo, lo_r) and np.array_equal(hi, hi_r)


@settings(max_examples=200, deadline=None)
@given(coord, coord, st.sampled_from([0.0, 0.4, -2.0]), st.lists(st.tuples(coord, coord), min_size=1, max_size=20))
def test_grid_cells_of_an_unrotated_origin_equal_the_inverse_transforms(ox, oy, yaw, pts) -> None:
    grid = OccupancyGrid(0.05, Pose2(ox, oy, yaw), np.zeros((10, 10), dtype=np.int8))
    p = np.array(pts, dtype=np.float64).reshape(-1, 2)
    local = grid.origin.inverse().transform_points(p)
    expected = np.c_[np.floor(local[:, 1] / 0.05), np.floor(local[:, 0] / 0.05)].astype(np.int64)
    assert np.array_equal(grid.world_to_cell(p), expected)


@pytest.mark.parametrize("m", range(1, 80))
def test_view_indices_are_the_rounded_linspace(m: int) -> None:
    expected = np.unique(np.linspace(0, m - 1, min(3, m)).round().astype(np.int64)).tolist()
    assert view_indices(m) == expected


@settings(max_examples=300, deadline=None)
@given(st.lists(st.floats(-1e3, 1e3, allow_nan=False, width=64), min_size=2, max_size=2))
def test_a_dot_products_root_is_numpys_norm(v) -> None:
    """association / evidence: ``math.sqrt(d·d)`` for ``np.linalg.norm(d)`` of a 2-vector."""
    import math

    d = np.array(v, dtype=np.float64)
    assert math.sqrt(float(d.dot(d))) == float(np.linalg.norm(d))


@settings(max_examples=100, deadline=None)
@given(st.integers(2, 60), st.integers(0, 2**31 - 1))
def test_pairwise_squared_distances_and_means_keep_numpys_values(n: int, seed: int) -> None:
    """evidence.add_ray's ``dx² + dy²`` for ``np.sum(Δ ** 2, axis=-1)``; footprint_estimate's
    ``add.reduce / n`` for ``mean(axis=0)``; a share above one half in integers for ``np.mean(mask) > 0.5``."""
    rng = np.random.default_rng(seed)
    o = rng.normal(0.0, 3.0, (n, 2))
    dx = o[:, 0][:, None] - o[:, 0][None, :]
    dy = o[:, 1][:, None] - o[:, 1][None, :]
    assert np.array_equal(dx * dx + dy * dy, np.sum((o[:, None, :] - o[None, :, :]) ** 2, axis=-1))
    u = np.abs(rng.normal(0.0, 1.0, (n, 2)))
    assert np.array_equal(np.add.reduce(u, axis=0) / len(u), u.mean(axis=0))
    mask = rng.random(n) < rng.random()
    assert (2 * int(np.count_nonzero(mask)) > n) == bool(np.mean(mask) > 0.5)
    assert (2 * int(np.count_nonzero(mask)) >= n) == bool(np.mean(mask) >= 0.5)
