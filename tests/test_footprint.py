"""Footprint estimation from an object's evidence (app/ocslam/footprint.py): known answers."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from app.ocslam.classes import prior
from app.ocslam.evidence import ObjectEvidence
from app.ocslam.footprint import estimate_footprint


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
