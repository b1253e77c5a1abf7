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
