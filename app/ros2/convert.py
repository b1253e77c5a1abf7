"""Our message dataclasses (``app.ocslam.messages``) ↔ ROS 2 messages of the ``rosbags`` type store.

``*_to_ros`` functions build ROS 2 message objects (serialise them with
``ros2_typestore().serialize_cdr(msg, msg.__msgtype__)``); ``*_from_ros`` functions accept messages of
either ROS version (ROS 1 and ROS 2 messages read by ``rosbags`` have the same field names, except
CameraInfo's ``K``/``k``), so the reader needs no per-version code.

Stamps are seconds (float) on our side and ``builtin_interfaces/Time`` on the ROS side; conversions
round to the nanosecond.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from app.ocslam.messages import (
    CLASS_INDEX,
    CLASS_NAMES,
    CameraInfo,
    Detection,
    Detections,
    GroundTruthObject,
    GroundTruthObstacle,
    Image,
    LaserScan,
    OccupancyGrid,
    TrackedObject,
    Twist,
)
from app.ocslam.se2 import Pose2
from app.ros2.topics import YOLO_COLUMNS
from app.ros2.typestore import ros2_typestore

FloatArray = NDArray[np.float64]
_ZERO_COV = np.zeros(36, dtype=np.float64)
_ZERO_COV.setflags(write=False)
_TYPES: dict[str, Any] = {}


def _t(name: str):
    cls = _TYPES.get(name)
    if cls is None:
        cls = _TYPES[name] = ros2_typestore().types[name]
    return cls


# ----------------------------------------------------------------------------------------------
# time, headers, poses
# ----------------------------------------------------------------------------------------------
def to_ns(t: float) -> int:
    """Seconds → integer nanoseconds (bag log time)."""
    return int(round(float(t) * 1e9))


def to_time(t: float):
    ns = to_ns(t)
    return _t("builtin_interfaces/msg/Time")(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def from_time(stamp: Any) -> float:
    """``builtin_interfaces/Time`` (ROS 2: sec/nanosec; ROS 1: sec/nanosec too in rosbags) → seconds."""
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


def header(t: float, frame_id: str):
    return _t("std_msgs/msg/Header")(stamp=to_time(t), frame_id=frame_id)


def quat_from_yaw(yaw: float):
    return _t("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0))


def yaw_from_quat(q: Any) -> float:
    """Heading of a quaternion: the yaw of its rotated x axis (exact for planar rotations)."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def pose_to_ros(T: Pose2, z: float = 0.0):
    P = _t("geometry_msgs/msg/Pose")
    return P(position=_t("geometry_msgs/msg/Point")(x=float(T.x), y=float(T.y), z=float(z)), orientation=quat_from_yaw(T.yaw))


def pose_from_ros(p: Any) -> Pose2:
    return Pose2(float(p.position.x), float(p.position.y), yaw_from_quat(p.orientation))


def matrix_to_transform(T: FloatArray):
    """(4, 4) homogeneous matrix → geometry_msgs/Transform."""
    T = np.asarray(T, dtype=np.float64)
    x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
    return _t("geometry_msgs/msg/Transform")(
        translation=_t("geometry_msgs/msg/Vector3")(x=float(T[0, 3]), y=float(T[1, 3]), z=float(T[2, 3])),
        rotation=_t("geometry_msgs/msg/Quaternion")(x=float(x), y=float(y), z=float(z), w=float(w)),
    )


def transform_to_matrix(tr: Any) -> FloatArray:
    """geometry_msgs/Transform (or Pose: position/orientation) → (4, 4) matrix."""
    t = getattr(tr, "translation", None) or tr.position
    q = getattr(tr, "rotation", None) or tr.orientation
    T = np.eye(4)
    n = math.sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w) or 1.0
    T[:3, :3] = Rotation.from_quat([q.x / n, q.y / n, q.z / n, q.w / n]).as_matrix()
    T[:3, 3] = [t.x, t.y, t.z]
    return T


def pose2_to_matrix(T: Pose2) -> FloatArray:
    M = np.eye(4)
    M[:2, :2] = [[math.cos(T.yaw), -math.sin(T.yaw)], [math.sin(T.yaw), math.cos(T.yaw)]]
    M[:2, 3] = [T.x, T.y]
    return M


def transform_stamped(t: float, parent: str, child: str, T: Pose2 | FloatArray):
    """geometry_msgs/TransformStamped of a planar ``Pose2`` (fast path) or a ``(4, 4)`` matrix."""
    if isinstance(T, Pose2):
        tr = _t("geometry_msgs/msg/Transform")(
            translation=_t("geometry_msgs/msg/Vector3")(x=float(T.x), y=float(T.y), z=0.0), rotation=quat_from_yaw(T.yaw))
    else:
        tr = matrix_to_transform(np.asarray(T, dtype=np.float64))
    return _t("geometry_msgs/msg/TransformStamped")(header=header(t, parent), child_frame_id=child, transform=tr)


def tf_message(transforms: Sequence[Any]):
    return _t("tf2_msgs/msg/TFMessage")(transforms=list(transforms))


# ----------------------------------------------------------------------------------------------
# sensors
# ----------------------------------------------------------------------------------------------
def scan_to_ros(scan: LaserScan):
    r = np.asarray(scan.ranges, dtype=np.float32)
    n = len(r)
    return _t("sensor_msgs/msg/LaserScan")(
        header=header(scan.stamp, scan.frame_id),
        angle_min=float(scan.angle_min),
        angle_max=float(scan.angle_min + scan.angle_increment * max(n - 1, 0)),
        angle_increment=float(scan.angle_increment),
        time_increment=0.0,
        scan_time=0.0,
        range_min=float(scan.range_min),
        range_max=float(scan.range_max),
        ranges=r,
        intensities=np.zeros(0, dtype=np.float32),
    )


def scan_from_ros(msg: Any) -> LaserScan:
    """Any LaserScan → ours. Ranges are float32 on the wire; they come back as float64."""
    return LaserScan(
        stamp=from_time(msg.header.stamp),
        angle_min=float(msg.angle_min),
        angle_increment=float(msg.angle_increment),
        range_min=float(msg.range_min),
        range_max=float(msg.range_max),
        ranges=np.asarray(msg.ranges, dtype=np.float64),
        frame_id=str(msg.header.frame_id),
    )


def odom_to_ros(t: float, T_odom_base: Pose2, linear_x: float = 0.0, angular_z: float = 0.0,
                frame_id: str = "odom", child_frame_id: str = "base_footprint"):
    V = _t("geometry_msgs/msg/Vector3")
    cov = _ZERO_COV
    return _t("nav_msgs/msg/Odometry")(
        header=header(t, frame_id),
        child_frame_id=child_frame_id,
        pose=_t("geometry_msgs/msg/PoseWithCovariance")(pose=pose_to_ros(T_odom_base), covariance=cov),
        twist=_t("geometry_msgs/msg/TwistWithCovariance")(
            twist=_t("geometry_msgs/msg/Twist")(linear=V(x=float(linear_x), y=0.0, z=0.0), angular=V(x=0.0, y=0.0, z=float(angular_z))),
            covariance=cov,
        ),
    )


def odom_from_ros(msg: Any) -> tuple[float, Pose2]:
    """nav_msgs/Odometry → ``(stamp, T_odom_base)``."""
    return from_time(msg.header.stamp), pose_from_ros(msg.pose.pose)


def twist_to_ros(tw: Twist):
    V = _t("geometry_msgs/msg/Vector3")
    return _t("geometry_msgs/msg/Twist")(linear=V(x=float(tw.linear_x), y=0.0, z=0.0),
                                         angular=V(x=0.0, y=0.0, z=float(tw.angular_z)))


def camera_info_to_ros(info: CameraInfo, t: float):
    K = np.asarray(info.K, dtype=np.float64)
    P = np.zeros((3, 4))
    P[:, :3] = K
    return _t("sensor_msgs/msg/CameraInfo")(
        header=header(t, info.frame_id),
        height=int(info.height),
        width=int(info.width),
        distortion_model="plumb_bob",
        d=np.zeros(5, dtype=np.float64),
        k=K.reshape(-1).copy(),
        r=np.eye(3).reshape(-1),
        p=P.reshape(-1),
        binning_x=0,
        binning_y=0,
        roi=_t("sensor_msgs/msg/RegionOfInterest")(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
    )


def camera_info_from_ros(msg: Any) -> CameraInfo:
    k = getattr(msg, "k", None)
    if k is None:
        k = msg.K  # ROS 1
    return CameraInfo(width=int(msg.width), height=int(msg.height), K=np.asarray(k, dtype=np.float64).reshape(3, 3),
                      frame_id=str(msg.header.frame_id))


def image_to_compressed(image: Image, quality: int = 95, fmt: str = "jpeg"):
    """RGB8 image → sensor_msgs/CompressedImage (``jpeg`` at ``quality``, or lossless ``png``)."""
    import cv2

    bgr = cv2.cvtColor(np.ascontiguousarray(image.data), cv2.COLOR_RGB2BGR)
    if fmt == "png":
        ok, buf = cv2.imencode(".png", bgr)
    else:
        ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise ValueError("image encoding failed")
    return _t("sensor_msgs/msg/CompressedImage")(header=header(image.stamp, image.frame_id),
                                                 format=f"rgb8; {fmt} compressed bgr8",
                                                 data=np.frombuffer(buf.tobytes(), dtype=np.uint8))


def image_from_compressed(msg: Any) -> Image:
    import cv2

    bgr = cv2.imdecode(np.asarray(msg.data, dtype=np.uint8), cv2.IMREAD_COLOR)
    if bgr is None:
        raise ValueError(f"undecodable compressed image ({msg.format!r})")
    return Image(stamp=from_time(msg.header.stamp), data=cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB),
                 frame_id=str(msg.header.frame_id))


def image_from_raw(msg: Any) -> Image:
    """sensor_msgs/Image (rgb8, bgr8, mono8) → RGB8."""
    h, w = int(msg.height), int(msg.width)
    enc = str(msg.encoding).lower()
    raw = np.asarray(msg.data, dtype=np.uint8)
    step = int(msg.step)
    if enc in ("rgb8", "bgr8"):
        a = raw.reshape(h, step)[:, : w * 3].reshape(h, w, 3)
        a = a[..., ::-1] if enc == "bgr8" else a
    elif enc == "mono8":
        a = np.repeat(raw.reshape(h, step)[:, :w, None], 3, axis=2)
    else:
        raise ValueError(f"unsupported image encoding {msg.encoding!r} (rgb8, bgr8, mono8)")
    return Image(stamp=from_time(msg.header.stamp), data=np.ascontiguousarray(a), frame_id=str(msg.header.frame_id))


# ----------------------------------------------------------------------------------------------
# /yolo_boxes
# ----------------------------------------------------------------------------------------------
_YOLO_LABEL = re.compile(r"boxes stamp=(\d+)\.(\d{9}) image=(\d+)x(\d+)")


def yolo_boxes_to_ros(dets: Detections):
    """Detections → std_msgs/Float32MultiArray in the layout of :mod:`app.ros2.topics`."""
    n = len(dets.boxes)
    data = np.array([[b.x1, b.y1, b.x2, b.y2, b.class_id, b.confidence * 100.0] for b in dets.boxes],
                    dtype=np.float32).reshape(n, 6)
    ns = to_ns(dets.stamp)
    D = _t("std_msgs/msg/MultiArrayDimension")
    label = f"boxes stamp={ns // 1_000_000_000}.{ns % 1_000_000_000:09d} image={dets.image_width}x{dets.image_height}"
    layout = _t("std_msgs/msg/MultiArrayLayout")(
        dim=[D(label=label, size=n, stride=6 * n), D(label=YOLO_COLUMNS, size=6, stride=6)], data_offset=0)
    return _t("std_msgs/msg/Float32MultiArray")(layout=layout, data=data.reshape(-1))


def yolo_boxes_from_ros(msg: Any) -> Detections:
    dims = list(msg.layout.dim)
    m = _YOLO_LABEL.fullmatch(dims[0].label) if dims else None
    if m is None or len(dims) != 2 or dims[1].size != 6:
        raise ValueError("not an OCSLAM /yolo_boxes layout (see app/ros2/topics.py)")
    stamp = int(m.group(1)) + 1e-9 * int(m.group(2))
    rows = np.asarray(msg.data, dtype=np.float64)[msg.layout.data_offset:].reshape(-1, 6)[: dims[0].size]
    boxes = tuple(
        Detection(float(r[0]), float(r[1]), float(r[2]), float(r[3]), int(round(r[4])), float(np.float32(r[5])) / 100.0)
        for r in rows
    )
    return Detections(stamp=stamp, image_width=int(m.group(3)), image_height=int(m.group(4)), boxes=boxes)


# ----------------------------------------------------------------------------------------------
# objects, map, graph, markers
# ----------------------------------------------------------------------------------------------
def _hypothesis(class_id: str, score: float, pose):
    PwC = _t("geometry_msgs/msg/PoseWithCovariance")
    return _t("vision_msgs/msg/ObjectHypothesisWithPose")(
        hypothesis=_t("vision_msgs/msg/ObjectHypothesis")(class_id=class_id, score=float(score)),
        pose=PwC(pose=pose, covariance=np.zeros(36, dtype=np.float64)),
    )


def _detection3d(t: float, frame: str, ident: str, label: str, score: float, T: Pose2, size: tuple[float, float, float], z: float):
    V = _t("geometry_msgs/msg/Vector3")
    return _t("vision_msgs/msg/Detection3D")(
        header=header(t, frame),
        results=[_hypothesis(label, score, pose_to_ros(T, z))],
        bbox=_t("vision_msgs/msg/BoundingBox3D")(center=pose_to_ros(T, z), size=V(x=float(size[0]), y=float(size[1]), z=float(size[2]))),
        id=ident,
    )


def objects_to_ros(objects: Iterable[TrackedObject], t: float, frame_id: str = "map"):
    """The object map → vision_msgs/Detection3DArray (score = presence; ``id`` = track id)."""
    dets = [
        _detection3d(t, frame_id, str(o.id), o.label, o.presence, o.pose, (o.size_x, o.size_y, o.size_z),
                     o.size_z / 2 if o.size_z > 0 else 0.0)
        for o in objects
    ]
    return _t("vision_msgs/msg/Detection3DArray")(header=header(t, frame_id), detections=dets)


def objects_from_ros(msg: Any) -> list[TrackedObject]:
    out = []
    for d in msg.detections:
        h = d.results[0].hypothesis if d.results else None
        label = h.class_id if h is not None else "unknown"
        out.append(TrackedObject(
            id=int(d.id) if str(d.id).lstrip("-").isdigit() else len(out), label=label,
            pose=pose_from_ros(d.bbox.center), size_x=float(d.bbox.size.x), size_y=float(d.bbox.size.y),
            size_z=float(d.bbox.size.z), presence=float(h.score) if h is not None else 0.0,
            frame_id=str(d.header.frame_id or msg.header.frame_id),
        ))
    return out


def _color(r: float, g: float, b: float, a: float = 1.0):
    return _t("std_msgs/msg/ColorRGBA")(r=float(r), g=float(g), b=float(b), a=float(a))


def marker(t: float, frame_id: str, ns: str, ident: int, mtype: int, *, pose=None, scale=(1.0, 1.0, 1.0),
           color=(1.0, 1.0, 1.0, 1.0), points: FloatArray | None = None, text: str = "", action: int = 0):
    """A visualization_msgs/Marker with every field filled (``points``: ``(N, 3)``)."""
    M = _t("visualization_msgs/msg/Marker")
    Pt = _t("geometry_msgs/msg/Point")
    pts = [] if points is None else [Pt(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in np.asarray(points)]
    return M(
        header=header(t, frame_id), ns=ns, id=int(ident), type=int(mtype), action=int(action),
        pose=pose if pose is not None else pose_to_ros(Pose2()),
        scale=_t("geometry_msgs/msg/Vector3")(x=float(scale[0]), y=float(scale[1]), z=float(scale[2])),
        color=_color(*color), lifetime=_t("builtin_interfaces/msg/Duration")(sec=0, nanosec=0), frame_locked=False,
        points=pts, colors=[], texture_resource="",
        texture=_t("sensor_msgs/msg/CompressedImage")(header=header(0.0, ""), format="", data=np.zeros(0, np.uint8)),
        uv_coordinates=[], text=text, mesh_resource="",
        mesh_file=_t("visualization_msgs/msg/MeshFile")(filename="", data=np.zeros(0, np.uint8)),
        mesh_use_embedded_materials=False,
    )


_M_CUBE, _M_LINE_STRIP, _M_LINE_LIST, _M_SPHERE_LIST, _M_TEXT, _DELETEALL = 1, 4, 5, 7, 9, 3


def _class_rgb(label: str) -> tuple[float, float, float]:
    i = CLASS_INDEX.get(label, 0)
    h = (i * 0.61803398875) % 1.0  # golden-ratio hues, stable per class
    import colorsys

    return colorsys.hsv_to_rgb(h, 0.75, 0.95)


def object_markers(objects: Sequence[TrackedObject], t: float, frame_id: str = "map"):
    """Object map → MarkerArray: a DELETEALL, then a cube and a text label per object (RViz / Foxglove)."""
    ms = [marker(t, frame_id, "objects", 0, 0, action=_DELETEALL)]
    for o in objects:
        h = o.size_z if o.size_z > 0 else 0.3
        rgb = _class_rgb(o.label)
        ms.append(marker(t, frame_id, "objects", o.id, _M_CUBE, pose=pose_to_ros(o.pose, h / 2),
                         scale=(max(o.size_x, 0.02), max(o.size_y, 0.02), h), color=(*rgb, 0.6)))
        ms.append(marker(t, frame_id, "labels", o.id, _M_TEXT, pose=pose_to_ros(o.pose, h + 0.15),
                         scale=(0.0, 0.0, 0.12), color=(*rgb, 1.0), text=f"{o.label} {o.presence:.2f}"))
    return _t("visualization_msgs/msg/MarkerArray")(markers=ms)


def grid_to_ros(grid: OccupancyGrid, t: float | None = None):
    stamp = grid.stamp if t is None else t
    meta = _t("nav_msgs/msg/MapMetaData")(
        map_load_time=to_time(stamp), resolution=float(grid.resolution), width=int(grid.width), height=int(grid.height),
        origin=pose_to_ros(grid.origin))
    return _t("nav_msgs/msg/OccupancyGrid")(header=header(stamp, grid.frame_id), info=meta,
                                            data=np.asarray(grid.data, dtype=np.int8).reshape(-1).copy())


def grid_from_ros(msg: Any) -> OccupancyGrid:
    info = msg.info
    data = np.asarray(msg.data, dtype=np.int8).reshape(int(info.height), int(info.width))
    return OccupancyGrid(resolution=float(info.resolution), origin=pose_from_ros(info.origin), data=data,
                         stamp=from_time(msg.header.stamp), frame_id=str(msg.header.frame_id))


def pose_graph_markers(graph: Any, t: float, frame_id: str = "map"):
    """SLAM pose graph (nodes ``(K, 3)``, edges ``(M, 2)``, ``is_loop`` ``(M,)``) → MarkerArray:
    keyframes (spheres), odometry/scan-match edges (grey lines), loop closures (red lines)."""
    nodes = np.asarray(graph.nodes, dtype=np.float64).reshape(-1, 3)
    edges = np.asarray(graph.edges, dtype=np.int64).reshape(-1, 2)
    loop = np.asarray(graph.is_loop, dtype=bool).reshape(-1)
    xyz = np.column_stack([nodes[:, :2], np.full(len(nodes), 0.02)])

    def seg(mask):
        e = edges[mask]
        return xyz[e.reshape(-1)] if len(e) else np.zeros((0, 3))

    ms = [
        marker(t, frame_id, "keyframes", 0, _M_SPHERE_LIST, scale=(0.06, 0.06, 0.06), color=(0.2, 0.5, 1.0, 1.0), points=xyz),
        marker(t, frame_id, "edges", 0, _M_LINE_LIST, scale=(0.01, 0.0, 0.0), color=(0.6, 0.6, 0.6, 0.8), points=seg(~loop)),
        marker(t, frame_id, "loop_closures", 0, _M_LINE_LIST, scale=(0.02, 0.0, 0.0), color=(1.0, 0.1, 0.1, 1.0), points=seg(loop)),
    ]
    return _t("visualization_msgs/msg/MarkerArray")(markers=ms)


def pose_stamped(t: float, frame_id: str, T: Pose2):
    return _t("geometry_msgs/msg/PoseStamped")(header=header(t, frame_id), pose=pose_to_ros(T))


# ----------------------------------------------------------------------------------------------
# ground truth
# ----------------------------------------------------------------------------------------------
def ground_truth_to_ros(objects: Sequence[GroundTruthObject], obstacles: Sequence[GroundTruthObstacle], t: float = 0.0,
                        frame_id: str = "map"):
    """Ground truth (already in ``frame_id``) → ``(Detection3DArray, MarkerArray of footprints)``."""
    dets, ms = [], []
    for o in objects:
        fp = np.asarray(o.footprint, dtype=np.float64).reshape(-1, 2)
        local = o.pose.inverse().transform_points(fp) if len(fp) else np.zeros((0, 2))
        size = (np.ptp(local[:, 0]) if len(local) else 0.0, np.ptp(local[:, 1]) if len(local) else 0.0, o.height)
        dets.append(_detection3d(t, frame_id, str(o.id), o.label, 1.0, o.pose, size, (o.z_min + o.z_max) / 2))
        ms.append(_footprint_marker(t, frame_id, "objects_legged" if o.legged else "objects", o.id, fp, o.z_min, o.z_max,
                                    o.label))
    for i, ob in enumerate(obstacles):
        fp = np.asarray(ob.footprint, dtype=np.float64).reshape(-1, 2)
        ms.append(_footprint_marker(t, frame_id, "walls" if ob.kind == "wall" else "obstacles", i, fp, ob.z_min, ob.z_max,
                                    ob.name))
    return (_t("vision_msgs/msg/Detection3DArray")(header=header(t, frame_id), detections=dets),
            _t("visualization_msgs/msg/MarkerArray")(markers=ms))


def _footprint_marker(t, frame_id, ns, ident, fp, z_min, z_max, text):
    closed = np.vstack([fp, fp[:1]]) if len(fp) else fp
    pts = np.column_stack([closed, np.full(len(closed), float(z_min))])
    color = {"walls": (0.5, 0.5, 0.5, 1.0), "obstacles": (0.8, 0.6, 0.3, 1.0)}.get(ns, (0.1, 0.9, 0.2, 1.0))
    return marker(t, frame_id, ns, ident, _M_LINE_STRIP, scale=(0.02, 0.0, float(z_max - z_min)), color=color,
                  points=pts, text=text)


def ground_truth_from_ros(objects_msg: Any, footprints_msg: Any) -> tuple[list[GroundTruthObject], list[GroundTruthObstacle]]:
    """Inverse of :func:`ground_truth_to_ros` (objects are joined to their footprints by id)."""
    fps: dict[int, Any] = {}
    obstacles: list[GroundTruthObstacle] = []
    for m in footprints_msg.markers if footprints_msg is not None else []:
        pts = np.array([[p.x, p.y] for p in m.points], dtype=np.float64).reshape(-1, 2)
        poly = pts[:-1] if len(pts) > 1 and np.allclose(pts[0], pts[-1]) else pts
        z0 = float(m.points[0].z) if len(m.points) else 0.0
        if m.ns in ("objects", "objects_legged"):
            fps[int(m.id)] = (poly, z0, z0 + float(m.scale.z), m.ns == "objects_legged")
        else:
            obstacles.append(GroundTruthObstacle(footprint=poly, z_min=z0, z_max=z0 + float(m.scale.z),
                                                 kind="wall" if m.ns == "walls" else "obstacle", name=str(m.text),
                                                 frame_id=str(m.header.frame_id)))
    objects: list[GroundTruthObject] = []
    for d in objects_msg.detections if objects_msg is not None else []:
        ident = int(d.id)
        label = d.results[0].hypothesis.class_id if d.results else CLASS_NAMES[0]
        poly, z0, z1, legged = fps.get(ident, (np.zeros((0, 2)), 0.0, float(d.bbox.size.z), False))
        objects.append(GroundTruthObject(id=ident, label=label, pose=pose_from_ros(d.bbox.center), footprint=poly,
                                         z_min=z0, z_max=z1, legged=legged, frame_id=str(d.header.frame_id)))
    return objects, obstacles


# ----------------------------------------------------------------------------------------------
# exact sidecars: the float64 values the core used (LaserScan ranges and /yolo_boxes are float32)
# ----------------------------------------------------------------------------------------------
def _f64_array(label: str, rows: NDArray[np.float64], cols: int, col_label: str):
    D = _t("std_msgs/msg/MultiArrayDimension")
    rows = np.asarray(rows, dtype=np.float64).reshape(-1, cols)
    layout = _t("std_msgs/msg/MultiArrayLayout")(
        dim=[D(label=label, size=len(rows), stride=cols * len(rows)), D(label=col_label, size=cols, stride=cols)],
        data_offset=0)
    return _t("std_msgs/msg/Float64MultiArray")(layout=layout, data=rows.reshape(-1).copy())


def _stamp_label(kind: str, t: float) -> str:
    ns = to_ns(t)
    return f"{kind} stamp={ns // 1_000_000_000}.{ns % 1_000_000_000:09d}"


def exact_ranges_to_ros(scan: LaserScan):
    """``/ocslam/scan_ranges``: the scan's float64 ranges (``dim[0]`` = ``ranges stamp=S.N``)."""
    return _f64_array(_stamp_label("ranges", scan.stamp), np.asarray(scan.ranges, np.float64).reshape(-1, 1), 1, "range")


def exact_ranges_from_ros(msg: Any) -> NDArray[np.float64]:
    return np.asarray(msg.data, dtype=np.float64)[msg.layout.data_offset:].copy()


def exact_boxes_to_ros(dets: Detections):
    """``/ocslam/yolo_boxes``: the boxes in float64, confidence as a fraction (columns
    ``x1,y1,x2,y2,class_id,confidence``; ``dim[0]`` as ``/yolo_boxes``')."""
    rows = np.array([[b.x1, b.y1, b.x2, b.y2, b.class_id, b.confidence] for b in dets.boxes], np.float64)
    label = yolo_boxes_to_ros(Detections(dets.stamp, dets.image_width, dets.image_height)).layout.dim[0].label
    return _f64_array(label, rows.reshape(-1, 6), 6, "x1,y1,x2,y2,class_id,confidence")


def exact_boxes_from_ros(msg: Any) -> Detections:
    m = _YOLO_LABEL.fullmatch(msg.layout.dim[0].label) if msg.layout.dim else None
    if m is None:
        raise ValueError("not an OCSLAM /ocslam/yolo_boxes layout")
    rows = np.asarray(msg.data, dtype=np.float64)[msg.layout.data_offset:].reshape(-1, 6)
    boxes = tuple(Detection(float(r[0]), float(r[1]), float(r[2]), float(r[3]), int(round(r[4])), float(r[5])) for r in rows)
    return Detections(stamp=int(m.group(1)) + 1e-9 * int(m.group(2)), image_width=int(m.group(3)),
                      image_height=int(m.group(4)), boxes=boxes)
