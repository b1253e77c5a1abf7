"""Object evidence under loop-closure corrections: moving many keyframes at once is the same as one by one."""

from __future__ import annotations

import numpy as np

from app.ocslam.evidence import ObjectEvidence
from app.ocslam.se2 import Pose2


def _evidence(rng: np.random.Generator) -> ObjectEvidence:
    ev = ObjectEvidence()
    for k in range(30):
        ev.add_points(rng.uniform(0.0, 2.0, (5, 2)), kf=k)
        ev.add_ray(rng.uniform(-1, 1, 2), rng.uniform(-1, 1, 2), 1.0, kf=k)
    ev.add_ground_center(np.array([1.0, 2.0]), 0.9, kf=7)
    return ev


def test_many_keyframes_move_exactly_as_one_at_a_time() -> None:
    rng = np.random.default_rng(3)
    a, b = _evidence(np.random.default_rng(5)), _evidence(np.random.default_rng(5))
    deltas = {k: Pose2(*rng.uniform(-0.1, 0.1, 3)) for k in range(0, 40, 2)}  # 20 (some unknown to the evidence)
    a.transform(deltas)  # the vectorised path (more than 8 keyframes)
    for k, T in deltas.items():  # the per-keyframe path, one keyframe at a time
        b.transform({k: T})
    for name in ("points", "ray_origin", "ray_dir", "gp_center"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    untouched = _evidence(np.random.default_rng(5))
    odd = untouched.point_kf % 2 == 1
    np.testing.assert_array_equal(a.points[odd], untouched.points[odd])
    assert not np.array_equal(a.points[~odd], untouched.points[~odd])


def test_transform_says_whether_anything_moved() -> None:
    """A correction of keyframes the object was never seen from leaves it as it is (and says so), so the
    object map re-estimates only the objects that moved."""
    ev = ObjectEvidence()
    ev.add_points(np.array([[1.0, 0.0], [1.1, 0.0]]), kf=3)
    ev.add_ray(np.zeros(2), np.array([1.0, 0.0]), 1.0, kf=4)
    pts, ray_o = ev.points.copy(), ev.ray_origin.copy()
    assert not ev.transform({5: Pose2(1.0, 0.0, 0.0)})
    assert np.array_equal(ev.points, pts) and np.array_equal(ev.ray_origin, ray_o)
    assert ev.transform({4: Pose2(0.5, 0.0, 0.0)})  # the ray only
    assert np.array_equal(ev.points, pts) and np.array_equal(ev.ray_origin, [[0.5, 0.0]])
    assert ev.transform({3: Pose2(0.0, 1.0, 0.0)})
    np.testing.assert_allclose(ev.points, pts + [0.0, 1.0])
    ev.add_ground_center(np.array([2.0, 2.0]), 0.9, kf=9)
    assert ev.transform({9: Pose2(0.0, 0.0, 0.0)})  # the ground-plane centre was seen from keyframe 9
    many = {k: Pose2(0.0, 0.0, 0.0) for k in range(20, 40)}  # > 8 keyframes: the vectorised path
    assert not ev.transform(many)
    assert ev.transform({**many, 3: Pose2(0.0, 0.0, 0.0)})
