"""app.ros2: message conversion, the type store, the /yolo_boxes layout and the LIDAR extrinsics."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.ocslam.messages import (
    CameraInfo,
    Detection,
    Detections,
    GroundTruthObject,
    GroundTruthObstacle,
    Image,
    LaserScan,
    OccupancyGrid,
    TrackedObject,
)
from app.ocslam.se2 import Pose2
from app.ros2 import convert
from app.ros2.extrinsics import level_scan, matrix_from_xyzrpy, planar_mount
from app.ros2.typestore import ros2_typestore

STORE = ros2_typestore()


def cdr(msg):
    """Serialise and deserialise through CDR, as a bag does."""
    return STORE.deserialize_cdr(STORE.serialize_cdr(msg, msg.__msgtype__), msg.__msgtype__)


def test_vision_msgs_registered_with_definitions():
    text, _ = STORE.generate_msgdef("vision_msgs/msg/Detection3DArray", ros_version=2)
    assert "vision_msgs/Detection3D[] detections" in text
    assert "MSG: vision_msgs/ObjectHypothesisWithPose" in text
    assert STORE.hash_rihs01("vision_msgs/msg/Detection3D").startswith("RIHS01_")


def test_scan_round_trip_float32_ranges():
    r = np.array([0.5, np.inf, 1.25, 3.0, np.nan])
    s = LaserScan(stamp=12.34, angle_min=-math.pi, angle_increment=2 * math.pi / 5, range_min=0.12, range_max=3.5,
                  ranges=r, frame_id="base_scan")
    back = convert.scan_from_ros(cdr(convert.scan_to_ros(s)))
    assert back.stamp == pytest.approx(12.34, abs=1e-9)
    assert back.frame_id == "base_scan"
    np.testing.assert_allclose(back.ranges[[0, 2, 3]], r[[0, 2, 3]], rtol=1e-7)
    assert np.isinf(back.ranges[1]) and np.isnan(back.ranges[4])
    assert back.angle_increment == pytest.approx(s.angle_increment, rel=1e-7)


@settings(max_examples=40, deadline=None)
@given(st.floats(-50, 50), st.floats(-50, 50), st.floats(-math.pi, math.pi), st.floats(0, 1e5))
def test_odometry_and_tf_round_trip(x, y, yaw, t):
    T = Pose2(x, y, yaw)
    stamp, back = convert.odom_from_ros(cdr(convert.odom_to_ros(t, T, 0.1, -0.2)))
    assert stamp == pytest.approx(t, abs=1e-9)
    assert back.x == pytest.approx(x, abs=1e-12) and back.y == pytest.approx(y, abs=1e-12)
    assert abs(math.remainder(back.yaw - yaw, 2 * math.pi)) < 1e-12
    tf = cdr(convert.tf_message([convert.transform_stamped(t, "odom", "base_footprint", T)]))
    M = convert.transform_to_matrix(tf.transforms[0].transform)
    np.testing.assert_allclose(M, convert.pose2_to_matrix(T), atol=1e-12)
    assert tf.transforms[0].header.frame_id == "odom" and tf.transforms[0].child_frame_id == "base_footprint"


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-3.2, 3.2), min_size=3, max_size=3), st.lists(st.floats(-2, 2), min_size=3, max_size=3))
def test_3d_transform_round_trip(rpy, xyz):
    M = matrix_from_xyzrpy([*xyz, *rpy])
    back = convert.transform_to_matrix(cdr(convert.matrix_to_transform(M)))
    np.testing.assert_allclose(back, M, atol=1e-12)


def test_yolo_boxes_layout_and_round_trip():
    d = Detections(stamp=3.1, image_width=320, image_height=240,
                   boxes=(Detection(10.5, 20.25, 100.0, 200.75, 4, 0.876), Detection(0, 0, 5, 5, 10, 0.5)))
    msg = cdr(convert.yolo_boxes_to_ros(d))
    assert msg.layout.dim[0].label == "boxes stamp=3.100000000 image=320x240"
    assert (msg.layout.dim[0].size, msg.layout.dim[0].stride) == (2, 12)
    assert (msg.layout.dim[1].label, msg.layout.dim[1].size) == ("x1,y1,x2,y2,class_id,confidence_pct", 6)
    rows = np.asarray(msg.data).reshape(2, 6)
    # the paper's integer matrix is the floor of the recorded rows
    np.testing.assert_array_equal(np.floor(rows).astype(np.int32), d.yolo_boxes())
    back = convert.yolo_boxes_from_ros(msg)
    assert back.stamp == pytest.approx(3.1, abs=1e-9) and (back.image_width, back.image_height) == (320, 240)
    assert [b.class_id for b in back.boxes] == [4, 10]
    assert back.boxes[0].x1 == pytest.approx(10.5) and back.boxes[0].confidence == pytest.approx(0.876, abs=1e-6)
    empty = convert.yolo_boxes_from_ros(cdr(convert.yolo_boxes_to_ros(Detections(1.0, 320, 240))))
    assert len(empty) == 0


def test_yolo_boxes_rejects_foreign_layout():
    msg = convert.yolo_boxes_to_ros(Detections(1.0, 320, 240))
    msg.layout.dim[0].label = "something else"
    with pytest.raises(ValueError, match="layout"):
        convert.yolo_boxes_from_ros(msg)


def test_camera_info_and_jpeg_image():
    info = CameraInfo.from_fov(320, 240, 1.04)
    back = convert.camera_info_from_ros(cdr(convert.camera_info_to_ros(info, 2.0)))
    np.testing.assert_array_equal(back.K, info.K)
    assert (back.width, back.height, back.frame_id) == (320, 240, "camera_optical_frame")
    rgb = np.zeros((240, 320, 3), np.uint8)
    rgb[:, :160] = (200, 30, 30)  # red left half: channel order must survive the round trip
    img = convert.image_from_compressed(cdr(convert.image_to_compressed(Image(2.0, rgb))))
    assert img.data.shape == (240, 320, 3) and img.stamp == pytest.approx(2.0)
    assert abs(int(img.data[120, 40, 0]) - 200) < 6 and abs(int(img.data[120, 40, 2]) - 30) < 6
    png = convert.image_from_compressed(cdr(convert.image_to_compressed(Image(2.0, rgb), fmt="png")))
    np.testing.assert_array_equal(png.data, rgb)


def test_grid_round_trip_ros_layout():
    data = np.full((3, 4), -1, np.int8)
    data[0, 1] = 100
    data[2, 3] = 0
    g = OccupancyGrid(resolution=0.05, origin=Pose2(-1.0, 2.0, 0.0), data=data, stamp=4.0)
    back = convert.grid_from_ros(cdr(convert.grid_to_ros(g)))
    np.testing.assert_array_equal(back.data, data)
    assert back.origin.x == -1.0 and back.origin.y == 2.0 and back.resolution == pytest.approx(0.05)


def test_objects_and_markers():
    objs = [TrackedObject(id=3, label="chair", pose=Pose2(1, 2, 0.5), size_x=0.4, size_y=0.5, size_z=0.8, presence=0.9)]
    msg = cdr(convert.objects_to_ros(objs, 5.0))
    d = msg.detections[0]
    assert (d.id, d.results[0].hypothesis.class_id, d.header.frame_id) == ("3", "chair", "map")
    assert d.bbox.size.z == pytest.approx(0.8) and d.bbox.center.position.z == pytest.approx(0.4)
    back = convert.objects_from_ros(msg)[0]
    assert back.label == "chair" and back.pose.yaw == pytest.approx(0.5) and back.presence == pytest.approx(0.9)
    ma = cdr(convert.object_markers(objs, 5.0))
    assert [m.ns for m in ma.markers] == ["objects", "objects", "labels"]
    assert ma.markers[0].action == 3  # DELETEALL first, so markers of dropped objects disappear


def test_ground_truth_round_trip():
    sq = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    objs = [GroundTruthObject(id=7, label="table", pose=Pose2(0.5, 0.5, 0.0), footprint=sq, z_min=0.0, z_max=0.7,
                              legged=True, frame_id="map")]
    obst = [GroundTruthObstacle(footprint=sq + 5, z_min=0.0, z_max=2.5, kind="wall", name="w1", frame_id="map")]
    a, b = convert.ground_truth_to_ros(objs, obst)
    o2, ob2 = convert.ground_truth_from_ros(cdr(a), cdr(b))
    assert o2[0].id == 7 and o2[0].label == "table" and o2[0].legged and o2[0].z_max == pytest.approx(0.7)
    np.testing.assert_allclose(o2[0].footprint, sq)
    assert ob2[0].kind == "wall" and ob2[0].z_max == pytest.approx(2.5)
    np.testing.assert_allclose(ob2[0].footprint, sq + 5)


def _scan(ranges, angle_min=-math.pi):
    return LaserScan(stamp=0.0, angle_min=angle_min, angle_increment=2 * math.pi / len(ranges), range_min=0.1,
                     range_max=10.0, ranges=np.asarray(ranges, float), frame_id="laser")


def test_upside_down_lidar_mirrors_the_scan():
    # the hw2 robot: a 180° turn about y, 0.2 m forward (x → −x in the plane)
    T = matrix_from_xyzrpy([0.2, 0.0, 0.0, 0.0, math.pi, 0.0])
    r = np.linspace(1.0, 3.0, 360)
    s = _scan(r)
    level, T_base_level = level_scan(s, T)
    base_true = s.points() * [-1.0, 1.0] + [0.2, 0.0]  # what the sensor saw, in base_footprint
    base_est = T_base_level.transform_points(level.points())
    # every return lands where it was, one-to-one (exact re-binning for a mirrored 1° layout)
    assert len(base_est) == len(base_true)
    d = np.hypot(*(base_true[:, None, :] - base_est[None, :, :]).transpose(2, 0, 1)).min(axis=1)
    assert d.max() < 1e-9


def test_level_lidar_passes_through():
    T = matrix_from_xyzrpy([-0.032, 0.0, 0.17, 0.0, 0.0, 0.3])
    s = _scan(np.full(90, 2.0))
    level, pose = level_scan(s, T)
    assert level is s
    assert pose == Pose2(-0.032, 0.0, pytest.approx(0.3))


def test_tilted_lidar_projects_onto_the_floor():
    T = matrix_from_xyzrpy([0.0, 0.0, 0.3, 0.0, 0.2, 0.0])  # pitched 0.2 rad down
    s = _scan(np.full(360, 2.0))
    level, pose = level_scan(s, T)
    assert planar_mount(T).yaw == pytest.approx(0.0)
    # the forward beam's planar reach shrinks by cos(pitch); the sideways beam's does not
    fwd = level.ranges[180]
    side = level.ranges[270]
    assert fwd == pytest.approx(2.0 * math.cos(0.2), abs=1e-6) and side == pytest.approx(2.0, abs=1e-6)
