"""SE(2) group properties (hypothesis) and known answers."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from app.ocslam import se2
from app.ocslam.se2 import Pose2, wrap_angle

coord = st.floats(-50, 50, allow_nan=False, allow_infinity=False)
angle = st.floats(-10, 10, allow_nan=False, allow_infinity=False)
poses = st.builds(Pose2, coord, coord, angle.map(lambda a: float(wrap_angle(a))))


def close(a: Pose2, b: Pose2, tol: float = 1e-9) -> bool:
    return abs(a.x - b.x) < tol and abs(a.y - b.y) < tol and abs(float(wrap_angle(a.yaw - b.yaw))) < tol


def test_known_compose() -> None:
    T_map_odom = Pose2(1.0, 0.0, 0.0)
    T_odom_base = Pose2(0.0, 2.0, np.pi / 2)
    T = T_map_odom @ T_odom_base
    assert close(T, Pose2(1.0, 2.0, np.pi / 2))
    # a point 1 m ahead of the robot (x forward) is 1 m along +y of the map when facing +y
    np.testing.assert_allclose(T.transform_points([[1.0, 0.0]]), [[1.0, 3.0]], atol=1e-12)


def test_wrap_angle_range() -> None:
    a = np.linspace(-20, 20, 1001)
    w = wrap_angle(a)
    assert np.all(w >= -np.pi) and np.all(w < np.pi)
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-9)
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-9)


@settings(max_examples=200, deadline=None)
@given(poses, poses, poses)
def test_associative(a: Pose2, b: Pose2, c: Pose2) -> None:
    assert close((a @ b) @ c, a @ (b @ c), 1e-6)


@settings(max_examples=200, deadline=None)
@given(poses)
def test_inverse_is_identity(a: Pose2) -> None:
    assert close(a @ a.inverse(), Pose2(), 1e-9)
    assert close(a.inverse() @ a, Pose2(), 1e-9)


@settings(max_examples=200, deadline=None)
@given(poses, poses)
def test_between_and_vectorised_agree(a: Pose2, b: Pose2) -> None:
    d = a.between(b)
    assert close(a @ d, b, 1e-6)
    v = se2.between(a.as_array()[None], b.as_array()[None])[0]
    assert close(Pose2.from_array(v), d, 1e-9)
    m = a.as_matrix() @ b.as_matrix()
    assert close(Pose2.from_matrix(m), a @ b, 1e-6)


@settings(max_examples=100, deadline=None)
@given(poses, st.lists(st.tuples(coord, coord), min_size=1, max_size=10))
def test_transform_preserves_distances(a: Pose2, pts: list[tuple[float, float]]) -> None:
    p = np.array(pts)
    q = a.transform_points(p)
    np.testing.assert_allclose(
        np.linalg.norm(p[:, None] - p[None], axis=-1), np.linalg.norm(q[:, None] - q[None], axis=-1), atol=1e-7
    )
    np.testing.assert_allclose(a.inverse().transform_points(q), p, atol=1e-7)


def test_interpolate_midpoint_and_shortest_arc() -> None:
    stamps = np.array([0.0, 1.0])
    poses = np.array([[0.0, 0.0, np.pi - 0.1], [2.0, 4.0, -np.pi + 0.1]])
    mid = se2.interpolate(0.5, stamps, poses)
    np.testing.assert_allclose(mid[:2], [1.0, 2.0])
    assert abs(abs(mid[2]) - np.pi) < 1e-9  # through ±π, not through 0
    np.testing.assert_allclose(se2.interpolate(-1.0, stamps, poses), poses[0])
    np.testing.assert_allclose(se2.interpolate(9.0, stamps, poses), poses[1])


@settings(max_examples=60, deadline=None)
@given(poses, st.lists(st.tuples(coord, coord), min_size=2, max_size=12))
def test_scalar_paths_equal_the_vectorised_ones_to_the_bit(a: Pose2, pts: list[tuple[float, float]]) -> None:
    # Pose2's methods compute on Python floats, one point without arrays: the same IEEE operations
    p = np.array(pts)
    many = a.transform_points(p)
    for i in range(len(p)):
        assert a.transform_points(p[i]).tolist() == [many[i].tolist()]
    c, s = np.cos(np.float64(a.yaw)), np.sin(np.float64(a.yaw))
    np.testing.assert_array_equal(many[:, 0], c * p[:, 0] - s * p[:, 1] + a.x)
    np.testing.assert_array_equal(many[:, 1], s * p[:, 0] + c * p[:, 1] + a.y)
    b = Pose2(*pts[0], a.yaw / 3.0)
    assert tuple(a @ b) == tuple(se2.compose(a.as_array(), b.as_array()).tolist())
    assert tuple(a.inverse()) == tuple(se2.inverse(a.as_array()).tolist())
    assert wrap_angle(a.yaw * 7.0) == float(wrap_angle(np.array([a.yaw * 7.0]))[0])
