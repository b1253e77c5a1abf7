"""Footprint estimation from an object's evidence (app/ocslam/footprint.py): known answers."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from app.ocslam.classes import prior
from app.ocslam.evidence import ObjectEvidence
from app.ocslam.footprint_estimate import estimate_footprint


def _face(x: float, y0: float, y1: float, n: int = 30) -> np.ndarray:
    """(n, 2) points of a face along y at x (object frame)."""
    return np.c_[np.full(n, x), np.linspace(y0, y1, n)]


def test_a_face_seen_only_through_cut_boxes_extends_away_from_the_robot() -> None:
    # a sofa's 1.0 m end filling the frame: every box was cut by the image border (ray weight 0)
    ev = ObjectEvidence()
    for k, oy in enumerate((-0.2, 0.0, 0.2)):
        ev.add_points(_face(2.0, -0.5, 0.5))
        ev.add_ray(np.array([4.0, oy]), np.array([-1.0, 0.0]), weight=0.0, open_side=1 if k % 2 else -1)
    fp = estimate_footprint(ev, prior("chair"))
    assert fp is not None
    c = fp.center
    sizes = sorted((fp.size_x, fp.size_y))
    assert sizes[0] >= 0.95 and abs(sizes[1] - 1.1) < 0.15  # face kept (1.0 m), depth from the class prior
    assert c[0] < 2.0 - 0.4 and abs(c[1]) < 0.05  # behind the face, seen from +x
    assert fp.contains(ev.points, margin=0.02).all()


def test_a_blob_seen_only_through_cut_boxes_is_not_extrapolated() -> None:
    ev = ObjectEvidence()
    rng = np.random.default_rng(0)
    ev.add_points(np.array([2.0, 0.0]) + rng.uniform(-0.1, 0.1, (40, 2)))
    ev.add_ray(np.array([4.0, 0.0]), np.array([-1.0, 0.0]), weight=0.0, open_side=1)
    fp = estimate_footprint(ev, prior("chair"))
    assert fp is not None
    assert max(fp.size_x, fp.size_y) <= 0.25
    np.testing.assert_allclose(fp.center, [2.0, 0.0], atol=0.05)


@given(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3), st.integers(2, 16))
@settings(max_examples=300, deadline=None)
def test_linspace_equals_numpys(start: float, stop: float, num: int) -> None:
    from app.ocslam.footprint import linspace

    assert np.array_equal(linspace(start, stop, num), np.linspace(start, stop, num))
    assert np.array_equal(linspace(start, start, num), np.linspace(start, start, num))


@given(st.lists(st.tuples(st.floats(-5, 5), st.floats(-5, 5)), min_size=1, max_size=40),
       st.floats(-5, 5), st.floats(-5, 5), st.floats(0.05, 3), st.floats(0.05, 3), st.floats(-4, 4), st.floats(0, 0.3))
@settings(max_examples=200, deadline=None)
def test_contains_point_agrees_with_contains(pts, cx, cy, sx, sy, yaw, margin) -> None:
    from app.ocslam.footprint import Footprint

    fp = Footprint(np.array([cx, cy]), yaw, sx, sy)
    p = np.array(pts, dtype=np.float64)
    assert [fp.contains_point(q, margin) for q in p] == list(fp.contains(p, margin))


def test_the_point_shape_cache_follows_every_change_of_the_points() -> None:
    """estimate_footprint keeps what it derives from the points on the evidence; a new ray reuses it, while
    new points, points moved in place by a correction and replaced arrays all give a fresh estimate."""
    from app.ocslam.se2 import Pose2

    def fresh(ev: ObjectEvidence):
        return estimate_footprint(ObjectEvidence.from_state_dict(ev.state_dict()), prior("sofa"))

    def same(a, b) -> bool:
        return np.allclose(a.center, b.center, atol=1e-12) and (a.yaw, a.size_x, a.size_y) == (b.yaw, b.size_x, b.size_y)

    ev = ObjectEvidence()
    ev.add_points(_face(2.0, -0.8, 0.8), kf=1)
    ev.add_ray(np.array([0.0, 0.0]), np.array([1.0, 0.0]), 1.0, kf=1)
    a = estimate_footprint(ev, prior("sofa"))
    cached = ev.shape_cache
    ev.add_ray(np.array([0.0, 1.0]), np.array([1.0, -0.5]), 1.0, kf=1)  # a ray only: the points' shape is kept
    b = estimate_footprint(ev, prior("sofa"))
    assert ev.shape_cache is cached and same(b, fresh(ev))
    ev.transform({1: Pose2(0.5, 0.2, 0.3)})  # in place: the revision changes
    c = estimate_footprint(ev, prior("sofa"))
    assert ev.shape_cache is not cached and same(c, fresh(ev)) and not same(c, a)
    ev.add_points(_face(2.6, -0.8, 0.8), kf=2)  # new arrays
    d = estimate_footprint(ev, prior("sofa"))
    assert same(d, fresh(ev)) and not same(d, c)
