"""The matcher recovers known offsets on synthetic scans; branch and bound equals brute force."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from app.ocslam.se2 import Pose2, compose
from app.ocslam.slam.field import build_field
from app.ocslam.slam.matcher import _rotated_cells, _scores, correlative_search, refine
from app.ocslam.slam.synthetic import room_world, simulate_scan

SEGS = room_world()
TRUTH0 = Pose2(3.0, 2.5, 0.4)


def _points(pose: Pose2, noise=0.0, seed=0):
    sc = simulate_scan(pose, SEGS, n_beams=360, range_max=6.0, noise_std=noise, rng=np.random.default_rng(seed))
    return sc.points()


# the map: two scans from nearby poses, in the world frame
MAP_PTS = np.vstack([TRUTH0.transform_points(_points(TRUTH0)), Pose2(3.3, 2.2, 0.0).transform_points(_points(Pose2(3.3, 2.2, 0.0)))])
FIELD = build_field(MAP_PTS, 0.05, 0.07, margin_m=1.0)


@settings(max_examples=25, deadline=None)
@given(
    st.floats(-0.25, 0.25),
    st.floats(-0.25, 0.25),
    st.floats(-0.3, 0.3),
    st.integers(0, 1000),
)
def test_recovers_offset_inside_window(dx, dy, dyaw, seed):
    truth = Pose2(TRUTH0.x + dx, TRUTH0.y + dy, TRUTH0.yaw + dyaw)
    pts = _points(truth, noise=0.01, seed=seed)
    init = TRUTH0.as_array()  # the prediction is off by (dx, dy, dyaw)
    res = correlative_search(FIELD, pts, init, 0.3, 0.35, np.radians(1.0))
    assert res is not None
    ref = refine(FIELD, pts, res.pose)
    err = ref.pose - truth.as_array()
    assert np.hypot(err[0], err[1]) < 0.02
    assert abs(np.degrees(err[2])) < 0.5
    assert ref.inlier_fraction > 0.8


def test_branch_and_bound_is_exact():
    truth = Pose2(3.12, 2.41, 0.47)
    pts = _points(truth, noise=0.02, seed=3)
    center = TRUTH0.as_array()
    step = np.radians(1.0)
    res = correlative_search(FIELD, pts, center, 0.4, 0.2, step)
    # brute force over the same lattice
    w = 8
    yaws = center[2] + np.arange(-11, 12) * step
    rows, cols = _rotated_cells(FIELD, pts, center[:2], yaws)
    a, ox, oy = np.meshgrid(np.arange(len(yaws)), np.arange(-w, w + 1), np.arange(-w, w + 1), indexing="ij")
    sc = _scores(FIELD.score, rows, cols, a.ravel(), ox.ravel(), oy.ravel())
    assert res is not None
    assert res.score == sc.max()


def test_refine_with_prior_and_no_map_overlap():
    # far outside the map: no correspondences, the pose stays at the prior
    pts = _points(TRUTH0)
    init = np.array([50.0, 50.0, 0.0])
    ref = refine(FIELD, pts, init, prior=init, prior_info=np.ones(3))
    assert np.allclose(ref.pose, init)
    assert ref.inlier_fraction == 0.0
    assert correlative_search(FIELD, pts, init, 0.3, 0.2, 0.02, min_score=0.1) is None


def test_compose_consistency_of_scan_frame():
    # matching a scan taken from the map pose itself returns that pose
    pts = _points(TRUTH0)
    res = correlative_search(FIELD, pts, compose(TRUTH0.as_array(), [0.1, -0.1, 0.05]), 0.3, 0.3, np.radians(1.0))
    ref = refine(FIELD, pts, res.pose)
    assert np.allclose(ref.pose, TRUTH0.as_array(), atol=2e-3)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-3, 3), min_size=9, max_size=9), st.lists(st.floats(-10, 10), min_size=3, max_size=3))
def test_solve3_matches_numpy_on_symmetric_positive_definite_systems(m, g):
    from app.ocslam.slam.matcher import _solve3

    M = np.array(m).reshape(3, 3)
    A = M @ M.T + 0.5 * np.eye(3)  # symmetric positive definite, condition bounded
    b = np.array(g)
    np.testing.assert_allclose(_solve3(A, b), -np.linalg.solve(A + 1e-9 * np.eye(3), b), rtol=1e-7, atol=1e-9)
    assert _solve3(-1e-9 * np.eye(3), b) is None  # exactly singular after the 1e-9 ridge
