"""RobotModel: extrinsics and wheel geometry read from the URDF, with known answers."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
import yourdfpy
from hypothesis import given, settings
from hypothesis import strategies as st

from app.config import Config
from app.ocslam.messages import CameraInfo
from app.ocslam.se2 import Pose2
from app.sim.robot_model import DEFAULT_URDF, RobotModel, RobotModelError, frame_transform

ROBOT = RobotModel.load()
URDF_TEXT = DEFAULT_URDF.read_text()

# REP-103 optical frame expressed in the body frame: z_opt = x_body, x_opt = -y_body, y_opt = -z_body
R_BODY_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def test_default_urdf_is_the_project_asset() -> None:
    assert DEFAULT_URDF.is_file() and DEFAULT_URDF.parts[-3:] == ("assets", "urdf", "turtlebot3_burger.urdf")
    assert ROBOT.urdf_path == DEFAULT_URDF


def test_wheels_match_the_public_dimensions_and_the_config() -> None:
    assert ROBOT.wheel_radius_m == pytest.approx(0.033, abs=1e-9)
    assert ROBOT.wheel_separation_m == pytest.approx(0.160, abs=1e-9)
    assert ROBOT.wheel_joint_names == ("wheel_left_joint", "wheel_right_joint")
    cfg = Config().robot  # odometry uses the config; the two must agree
    assert cfg.wheel_radius_m == pytest.approx(ROBOT.wheel_radius_m)
    assert cfg.wheel_separation_m == pytest.approx(ROBOT.wheel_separation_m)


def test_lidar_extrinsics() -> None:
    assert ROBOT.lidar_height_m == pytest.approx(0.173, abs=0.002)
    np.testing.assert_allclose(ROBOT.T_base_scan[:3, :3], np.eye(3), atol=1e-12)  # scan x = robot x
    assert ROBOT.T_base_scan[0, 3] == pytest.approx(-0.032, abs=1e-9)  # 3 cm behind the axle
    assert ROBOT.T_base_scan_2d() == Pose2(-0.032, 0.0, 0.0)
    # a return 2 m straight ahead of the LIDAR is 1.968 m ahead of base_footprint
    np.testing.assert_allclose(
        ROBOT.T_base_scan_2d().transform_points(np.array([[2.0, 0.0]])), [[1.968, 0.0]]
    )


def test_camera_extrinsics_follow_rep103() -> None:
    assert ROBOT.camera_height_m == pytest.approx(0.19, abs=0.005)
    np.testing.assert_allclose(
        ROBOT.T_base_camera_link[:3, :3], np.eye(3), atol=1e-12
    )  # no pitch, looks along +x
    np.testing.assert_allclose(ROBOT.T_base_camera_optical[:3, :3], R_BODY_OPTICAL, atol=1e-12)
    np.testing.assert_allclose(ROBOT.T_base_camera_optical[:3, 3], ROBOT.T_base_camera_link[:3, 3])
    assert -0.015 <= ROBOT.T_base_camera_link[0, 3] <= 0.035
    assert ROBOT.T_base_camera_link[1, 3] == pytest.approx(0.011)
    T_opt_base = np.linalg.inv(ROBOT.T_base_camera_optical)
    cam = ROBOT.T_base_camera_optical[:3, 3]
    # a point 1 m ahead of the camera, at its height: optical z = +1, centred
    np.testing.assert_allclose(T_opt_base @ np.append(cam + [1, 0, 0], 1), [0, 0, 1, 1], atol=1e-12)
    # left of the robot is -x in the image, up is -y
    np.testing.assert_allclose(T_opt_base @ np.append(cam + [1, 0.2, 0.1], 1), [-0.2, -0.1, 1, 1], atol=1e-12)
    # a point 1 m ahead of the robot on the floor is in front of the camera and below the image centre
    p_floor = T_opt_base @ [1.0, 0.0, 0.0, 1.0]
    assert p_floor[2] == pytest.approx(1.0 - cam[0]) and p_floor[1] == pytest.approx(cam[2])


def test_projection_with_K() -> None:
    """P = K [R | t] with the extrinsics from RobotModel puts a floor point 1 m ahead below the centre."""
    info = CameraInfo.from_fov(640, 480, 1.04)
    T_opt_base = np.linalg.inv(ROBOT.T_base_camera_optical)
    P = info.K @ T_opt_base[:3, :]
    uvw = P @ [1.0, 0.0, 0.0, 1.0]
    u, v = uvw[:2] / uvw[2]
    assert u == pytest.approx(
        info.cx + info.fx * ROBOT.T_base_camera_link[1, 3] / uvw[2]
    )  # camera is 11 mm left
    assert v == pytest.approx(info.cy + info.fy * 0.19 / (1.0 - ROBOT.T_base_camera_link[0, 3]))
    assert 0 <= v < info.height  # the floor 1 m ahead is visible (the paper's detections rely on it)


def test_frame_transform_agrees_with_yourdfpy_for_every_pair() -> None:
    urdf = yourdfpy.URDF.load(str(DEFAULT_URDF), load_meshes=False)
    names = list(urdf.link_map)
    for a, b in itertools.permutations(names, 2):
        T_ab = frame_transform(urdf, a, b)
        np.testing.assert_allclose(
            T_ab, urdf.get_transform(frame_to=b, frame_from=a), atol=1e-12, err_msg=f"{a}->{b}"
        )
        np.testing.assert_allclose(T_ab @ frame_transform(urdf, b, a), np.eye(4), atol=1e-12)
    for name in names:
        np.testing.assert_allclose(
            ROBOT.T_base(name), frame_transform(urdf, "base_footprint", name), atol=1e-12
        )
    with pytest.raises(RobotModelError, match="no_such_link"):
        frame_transform(urdf, "base_link", "no_such_link")


@settings(max_examples=50, deadline=None)
@given(
    st.lists(st.floats(-5, 5, allow_nan=False), min_size=3, max_size=3),
)
def test_scan_to_base_points_match_the_3d_transform(xyz: list[float]) -> None:
    """The 2D LIDAR pose and the full 3D pose agree on in-plane points."""
    p_scan = np.array([xyz[0], xyz[1], 0.0, 1.0])
    p_base = ROBOT.T_base_scan @ p_scan
    np.testing.assert_allclose(
        ROBOT.T_base_scan_2d().transform_points(p_scan[None, :2])[0], p_base[:2], atol=1e-12
    )
    assert p_base[2] == pytest.approx(ROBOT.lidar_height_m)


def test_model_arrays_are_read_only() -> None:
    with pytest.raises(ValueError):
        ROBOT.T_base_scan[0, 3] = 1.0
    T = ROBOT.T_base("base_scan")
    T[0, 3] = 1.0  # a copy
    assert ROBOT.T_base_scan[0, 3] == pytest.approx(-0.032)
    with pytest.raises(RobotModelError, match="nope"):
        ROBOT.T_base("nope")


# --------------------------------------------------------------------------------------------------
# bad input: clear errors
# --------------------------------------------------------------------------------------------------
def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "robot.urdf"
    path.write_text(text)
    return path


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(RobotModelError, match="not found"):
        RobotModel.load(tmp_path / "nope.urdf")


def test_malformed_xml(tmp_path: Path) -> None:
    with pytest.raises(RobotModelError, match="cannot parse"):
        RobotModel.load(_write(tmp_path, URDF_TEXT[: len(URDF_TEXT) // 2]))


def test_missing_frame(tmp_path: Path) -> None:
    text = URDF_TEXT.replace('link name="camera_optical_frame"', 'link name="camera_optical"').replace(
        'child link="camera_optical_frame"', 'child link="camera_optical"'
    )
    with pytest.raises(RobotModelError, match="camera_optical_frame"):
        RobotModel.load(_write(tmp_path, text))


def test_fixed_wheel_joint_is_rejected(tmp_path: Path) -> None:
    text = URDF_TEXT.replace(
        '<joint name="wheel_right_joint" type="continuous">', '<joint name="wheel_right_joint" type="fixed">'
    )
    assert text != URDF_TEXT
    with pytest.raises(RobotModelError, match="wheel_right_joint"):
        RobotModel.load(_write(tmp_path, text))


def test_other_dimensions_are_read_not_assumed(tmp_path: Path) -> None:
    """A wider robot with bigger wheels and a lower LIDAR reads back its own numbers."""
    text = (
        URDF_TEXT.replace('xyz="0 0.080 0.023"', 'xyz="0 0.120 0.040"')
        .replace('xyz="0 -0.080 0.023"', 'xyz="0 -0.120 0.040"')
        .replace('radius="0.033"', 'radius="0.050"')
        .replace('xyz="-0.032 0 0.163"', 'xyz="-0.050 0 0.100"')
    )
    robot = RobotModel.load(_write(tmp_path, text))
    assert robot.wheel_radius_m == pytest.approx(0.050)
    assert robot.wheel_separation_m == pytest.approx(0.240)
    assert robot.lidar_height_m == pytest.approx(0.110)
    assert robot.T_base_scan_2d() == Pose2(-0.05, 0.0, 0.0)


def test_swapped_wheels_are_rejected(tmp_path: Path) -> None:
    text = URDF_TEXT.replace('xyz="0 0.080 0.023"', "LEFT").replace(
        'xyz="0 -0.080 0.023"', 'xyz="0 0.080 0.023"'
    )
    text = text.replace("LEFT", 'xyz="0 -0.080 0.023"')
    with pytest.raises(RobotModelError, match="left wheel"):
        RobotModel.load(_write(tmp_path, text))
