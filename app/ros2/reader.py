"""Read a robot bag for replay: ROS 1 ``.bag``, rosbag2 sqlite3 (``.db3``) or MCAP, through ``rosbags``.

:func:`read_bag` opens the bag, checks that it holds what replay needs (a scan topic, and odometry from
``/odom`` or from ``/tf`` odom → base), collects the static transforms, the camera calibration and the
ground truth, and returns a :class:`Bag`: a time-ordered list of :class:`Event` s whose messages are
decoded only when used (images are decoded by the replay, not here). Topics that are missing or empty
are named in :attr:`Bag.warnings`.

Time: stamps and log times are seconds relative to :attr:`Bag.time_offset` (whole seconds subtracted
from wall-clock bags; 0 for OCSLAM's sim-time bags), so the core sees small, exact numbers.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app.ocslam.messages import CameraInfo, GroundTruthObject, GroundTruthObstacle
from app.ros2 import convert, topics
from app.ros2.errors import BagError
from app.ros2.typestore import ros1_typestore, ros2_typestore

log = logging.getLogger(__name__)

#: processing order of events logged at the same instant (as the live loop's step runs them)
PRIORITY = {"odom": 0, "tf": 0, "scan": 1, "scan_exact": 1.5, "image": 2, "image_raw": 2, "camera_info": 3, "boxes": 4,
            "boxes_exact": 4.5, "map": 5, "gt_pose": 6}
#: OCSLAM's float64 sidecars and the message kind each completes
EXACT_OF = {"scan_exact": "scan", "boxes_exact": "boxes"}

BASE_FRAMES = ("base_footprint", "base_link")


@dataclass
class BagTopics:
    """Topic names read by the replay (``replay.*_topic`` in the config)."""

    scan: str = topics.SCAN
    odom: str = topics.ODOM
    image: str = topics.IMAGE_COMPRESSED
    image_raw: str = topics.IMAGE_RAW
    camera_info: str = topics.CAMERA_INFO
    yolo_boxes: str = topics.YOLO_BOXES


@dataclass(slots=True)
class Event:
    """One message: log time ``t`` (s), what it is, and how to decode it (``decode()`` → our dataclass)."""

    t: float
    kind: str  # odom | tf | scan | image | image_raw | camera_info | boxes | map | gt_pose
    raw: bytes
    msgtype: str
    _decode: Callable[..., Any]
    extra: bytes | None = None  # OCSLAM's exact float64 sidecar of this message, if recorded

    def decode(self) -> Any:
        return self._decode(self)


@dataclass
class Bag:
    path: Path
    events: list[Event]
    time_offset: float
    duration_s: float
    topic_counts: dict[str, int]
    topic_types: dict[str, str]
    static_tf: dict[tuple[str, str], np.ndarray]  # (parent, child) → (4, 4)
    camera_info: CameraInfo | None
    ground_truth: tuple[list[GroundTruthObject], list[GroundTruthObstacle]] | None
    ocslam_recording: bool
    warnings: list[str] = field(default_factory=list)
    stamp_step_s: float | None = None  # sim bags: stamps are whole multiples of this
    odom_source: str = "odom"  # "odom" | "tf"
    base_frame: str = "base_footprint"

    @property
    def has_camera(self) -> bool:
        return self.camera_info is not None and any(e.kind in ("image", "image_raw") for e in self.events)

    @property
    def has_boxes(self) -> bool:
        return any(e.kind == "boxes" for e in self.events)

    def T_base(self, frame: str) -> np.ndarray | None:
        """(4, 4) pose of ``frame`` in the base frame, composed along ``/tf_static`` (None if unknown)."""
        return compose_static(self.static_tf, self.base_frame, frame)


def compose_static(static: dict[tuple[str, str], np.ndarray], base: str, frame: str) -> np.ndarray | None:
    """Pose of ``frame`` in ``base`` from ``(parent, child) → T_parent_child`` edges (a tree)."""
    if frame == base:
        return np.eye(4)
    parent_of = {c: (p, T) for (p, c), T in static.items()}
    T = np.eye(4)
    f = frame
    for _ in range(64):
        if f not in parent_of:
            break
        p, T_pc = parent_of[f]
        T = T_pc @ T
        if p == base:
            return T
        f = p
    # base may be below the chain's root (e.g. base_link → base_footprint): go through the common root
    T_root_base = compose_to_root(parent_of, base)
    T_root_frame = compose_to_root(parent_of, frame)
    if T_root_base is None or T_root_frame is None or T_root_base[0] != T_root_frame[0]:
        return None
    return np.linalg.inv(T_root_base[1]) @ T_root_frame[1]


def compose_to_root(parent_of: dict[str, tuple[str, np.ndarray]], frame: str) -> tuple[str, np.ndarray] | None:
    T = np.eye(4)
    f = frame
    for _ in range(64):
        if f not in parent_of:
            return f, T
        p, T_pc = parent_of[f]
        T = T_pc @ T
        f = p
    return None


def read_bag(path: str | Path, names: BagTopics | None = None, *, with_images: bool = True,
             only: set[str] | None = None) -> Bag:
    """Open ``path`` (a ``.bag`` file, or a rosbag2 folder / ``.mcap`` / ``.db3``) and index it for replay.

    ``only``: topic names to read (``--topics``); the rest is skipped. ``with_images=False`` leaves the
    camera images out (``--reuse-detections``). Raises :class:`BagError` with one clear line when the
    bag is missing, unreadable, or lacks a scan or odometry."""
    from rosbags.highlevel import AnyReader

    names = names or BagTopics()
    path = Path(path)
    if not path.exists():
        raise BagError(f"bag not found: {path}")
    paths = [path]
    if path.is_file() and path.suffix in (".mcap", ".db3"):
        if (path.parent / "metadata.yaml").exists():
            paths = [path.parent]
        else:
            raise BagError(f"{path}: a rosbag2 storage file needs the metadata.yaml of its bag folder beside it")
    if path.is_dir() and not (path / "metadata.yaml").exists():
        raise BagError(f"{path}: not a rosbag2 folder (no metadata.yaml) and not a ROS 1 .bag file")
    if path.is_file() and path.suffix != ".bag":
        raise BagError(f"{path}: not a bag (expected a ROS 1 .bag file or a rosbag2 folder)")
    try:
        reader = AnyReader(paths, default_typestore=ros1_typestore() if path.suffix == ".bag" else ros2_typestore())
        reader.open()
    except Exception as e:  # rosbags raises several types for corrupt files
        raise BagError(f"{path}: unreadable bag ({_one_line(e)})") from None
    try:
        return _index(reader, path, names, with_images, only)
    except BagError:
        raise
    except Exception as e:
        raise BagError(f"{path}: corrupt bag ({_one_line(e)})") from None
    finally:
        try:
            reader.close()
        except Exception:
            pass


def _one_line(e: BaseException) -> str:
    s = " ".join(str(e).split()) or type(e).__name__
    return s[:200]


def _index(reader: Any, path: Path, names: BagTopics, with_images: bool, only: set[str] | None) -> Bag:
    conns = reader.connections
    counts: dict[str, int] = {}
    types: dict[str, str] = {}
    for c in conns:
        counts[c.topic] = counts.get(c.topic, 0) + int(c.msgcount)
        types[c.topic] = c.msgtype
    warnings: list[str] = []
    ocslam = False
    try:
        import yaml

        from app.ros2.recorder import WRITER_KEY, WRITER_VALUE

        meta = path if path.is_dir() else path.parent
        info = yaml.safe_load((meta / "metadata.yaml").read_text(encoding="utf-8")) if (meta / "metadata.yaml").is_file() else {}
        custom = (info or {}).get("rosbag2_bagfile_information", {}).get("custom_data") or {}
        ocslam = custom.get(WRITER_KEY) == WRITER_VALUE
        step = float(custom[topics.STAMP_STEP_KEY]) if ocslam and topics.STAMP_STEP_KEY in custom else None
    except Exception:
        ocslam, step = False, None

    def want(topic: str) -> bool:
        return only is None or topic in only or topic in (topics.TF_STATIC,)

    kinds: dict[str, str] = {names.scan: "scan", names.odom: "odom", topics.TF: "tf", names.camera_info: "camera_info",
                             names.yolo_boxes: "boxes", topics.GT_POSE: "gt_pose"}
    if with_images:
        kinds[names.image] = "image"
        kinds[names.image_raw] = "image_raw"
    if ocslam:
        kinds[topics.MAP] = "map"
        kinds[topics.EXACT_RANGES] = "scan_exact"
        kinds[topics.EXACT_BOXES] = "boxes_exact"
    avail = {t: n for t, n in counts.items() if want(t)}  # what --topics lets through
    # what must be there
    for topic, what in ((names.scan, "scan"),):
        if avail.get(topic, 0) == 0:
            raise BagError(f"{path}: no {what} messages on {topic} "
                           f"({'topic missing' if topic not in avail else 'topic empty'}; topics: {', '.join(sorted(avail)) or 'none'}); "
                           f"set replay.scan_topic")
    for topic in (names.odom, names.camera_info, names.image if names.image in avail else names.image_raw):
        if topic in avail and avail[topic] == 0:
            warnings.append(f"topic {topic} is in the bag but empty")
    odom_source = "odom"
    if avail.get(names.odom, 0) == 0:
        if avail.get(topics.TF, 0) == 0:
            raise BagError(f"{path}: no odometry: {names.odom} is {'empty' if names.odom in avail else 'missing'} "
                           f"and there is no /tf (odom → base); set replay.odom_topic")
        odom_source = "tf"
        warnings.append(f"topic {names.odom} is {'empty' if names.odom in avail else 'missing'}: odometry from /tf odom → base")
    if names.image not in avail and names.image_raw not in avail:
        warnings.append(f"no camera topic ({names.image} or {names.image_raw}): mapping only")
    elif names.camera_info not in avail or avail[names.camera_info] == 0:
        warnings.append(f"topic {names.camera_info} is missing or empty: the camera is not used (mapping only)")

    start_ns = int(reader.start_time) if reader.message_count else 0
    offset_s = 0 if start_ns < 10**6 * 10**9 else start_ns // 10**9  # wall-clock bags: whole seconds off
    offset_ns = offset_s * 10**9
    snap = _snapper(step)

    def rel(ns: int) -> float:
        return snap((int(ns) - offset_ns) * 1e-9)

    static: dict[tuple[str, str], np.ndarray] = {}
    cam_info: CameraInfo | None = None
    gt_objs = gt_fps = None
    events: list[Event] = []
    store, is2 = reader.typestore, reader.is2  # kept: closing the reader empties its own reference

    def deser(raw: bytes, msgtype: str) -> Any:
        return store.deserialize_cdr(raw, msgtype) if is2 else store.deserialize_ros1(raw, msgtype)

    wanted_conns = [c for c in conns if want(c.topic) and (c.topic in kinds or c.topic in (topics.TF_STATIC, topics.GT_OBJECTS, topics.GT_FOOTPRINTS))]
    decoders = _decoders(deser, offset_s, odom_source, snap)
    base_frame = "base_footprint"
    for c, ts, raw in reader.messages(connections=wanted_conns):
        topic = c.topic
        if topic == topics.TF_STATIC:
            for tr in deser(raw, c.msgtype).transforms:
                static[(str(tr.header.frame_id).lstrip("/"), str(tr.child_frame_id).lstrip("/"))] = convert.transform_to_matrix(tr.transform)
            continue
        if topic == topics.GT_OBJECTS:
            gt_objs = deser(raw, c.msgtype)
            continue
        if topic == topics.GT_FOOTPRINTS:
            gt_fps = deser(raw, c.msgtype)
            continue
        kind = kinds[topic]
        if kind == "camera_info" and cam_info is None:
            cam_info = convert.camera_info_from_ros(deser(raw, c.msgtype))
        if kind == "tf":
            if odom_source != "tf":
                continue  # /tf only matters as the odometry source
        events.append(Event(rel(ts), kind, bytes(raw), c.msgtype, decoders.get(kind, _no_decoder)))
    if odom_source == "tf":
        base_frame = _tf_base(events)
        if base_frame is None:
            raise BagError(f"{path}: no odometry: {names.odom} is missing and /tf has no odom → base_footprint/base_link")
    else:
        for e in events:
            if e.kind == "odom":
                child = str(getattr(e._decode(e, raw_msg=True), "child_frame_id", ""))
                base_frame = child.lstrip("/") or "base_footprint"
                break
    events.sort(key=lambda e: (e.t, PRIORITY[e.kind]))  # stable: bag order within a kind
    if any(e.kind in EXACT_OF for e in events):  # fold each sidecar into the message it completes
        last: dict[str, Event] = {}
        kept = []
        for e in events:
            main = EXACT_OF.get(e.kind)
            if main is None:
                last[e.kind] = e
                kept.append(e)
            elif main in last and abs(last[main].t - e.t) < 1e-12 and last[main].extra is None:
                last[main].extra = e.raw
        events = kept
    duration = (events[-1].t - events[0].t) if events else 0.0
    gt = convert.ground_truth_from_ros(gt_objs, gt_fps) if gt_objs is not None else None
    return Bag(path=path, events=events, time_offset=float(offset_s), duration_s=duration, topic_counts=counts,
               topic_types=types, static_tf=static, camera_info=cam_info, ground_truth=gt, ocslam_recording=ocslam,
               warnings=warnings, odom_source=odom_source, base_frame=base_frame, stamp_step_s=step)


def _tf_base(events: list[Event]) -> str | None:
    for e in events:
        if e.kind == "tf":
            msg = e._decode(e, raw_msg=True)
            for tr in msg.transforms:
                if str(tr.header.frame_id).lstrip("/") == "odom" and str(tr.child_frame_id).lstrip("/") in BASE_FRAMES:
                    return str(tr.child_frame_id).lstrip("/")
    return None


def _snapper(step: float | None) -> Callable[[float], float]:
    """Restore sim stamps to the live run's floats: ``k × step`` when within a nanosecond of one."""
    if not step:
        return lambda t: t

    def snap(t: float) -> float:
        k = round(t / step)
        v = k * step
        return v if abs(v - t) < 1e-9 else t

    return snap


def _decoders(deser: Callable[[bytes, str], Any], offset_s: int, odom_source: str,
              snap: Callable[[float], float] = lambda t: t) -> dict[str, Callable]:
    """Per kind: ``decode(event, raw_msg=False)`` → our dataclass (or the ROS message with ``raw_msg``)."""

    def _rel_stamp(stamp: Any, offset: int) -> float:
        return snap(float(int(stamp.sec) - offset) + 1e-9 * float(stamp.nanosec))

    def shift(stamp_s: float) -> float:
        return stamp_s - offset_s

    def msg_of(e: Event) -> Any:
        return deser(e.raw, e.msgtype)

    def wrap(f):
        def d(e: Event, raw_msg: bool = False):
            m = msg_of(e)
            if raw_msg:
                return m
            if e.extra is not None:
                return f(m, deser(e.extra, "std_msgs/msg/Float64MultiArray"))
            return f(m)

        return d

    def scan(m, exact=None):
        from dataclasses import replace

        s = convert.scan_from_ros(m)
        s = replace(s, stamp=_rel_stamp(m.header.stamp, offset_s), frame_id=s.frame_id.lstrip("/"))
        if exact is not None:
            r = convert.exact_ranges_from_ros(exact)
            if len(r) == len(s.ranges):
                s = replace(s, ranges=r)
        return s

    def odom(m):
        _, T = convert.odom_from_ros(m)
        return _rel_stamp(m.header.stamp, offset_s), T

    def tf(m):
        for tr in m.transforms:
            if str(tr.header.frame_id).lstrip("/") == "odom" and str(tr.child_frame_id).lstrip("/") in BASE_FRAMES:
                from app.ocslam.se2 import Pose2

                M = convert.transform_to_matrix(tr.transform)
                import math

                return _rel_stamp(tr.header.stamp, offset_s), Pose2(float(M[0, 3]), float(M[1, 3]),
                                                                    math.atan2(M[1, 0], M[0, 0]))
        return None

    def image(m):
        from dataclasses import replace

        im = convert.image_from_compressed(m)
        return replace(im, stamp=_rel_stamp(m.header.stamp, offset_s))

    def image_raw(m):
        from dataclasses import replace

        im = convert.image_from_raw(m)
        return replace(im, stamp=_rel_stamp(m.header.stamp, offset_s))

    def camera_info(m):
        return convert.camera_info_from_ros(m)

    def boxes(m, exact=None):
        from dataclasses import replace

        d = convert.exact_boxes_from_ros(exact) if exact is not None else convert.yolo_boxes_from_ros(m)
        return replace(d, stamp=snap(d.stamp - offset_s))

    def grid(m):
        return None  # only its instant matters (the SLAM's lazy grid update)

    def gt_pose(m):
        return _rel_stamp(m.header.stamp, offset_s), convert.pose_from_ros(m.pose)

    return {"scan": wrap(scan), "odom": wrap(odom), "tf": wrap(tf), "image": wrap(image), "image_raw": wrap(image_raw),
            "camera_info": wrap(camera_info), "boxes": wrap(boxes), "map": wrap(grid), "gt_pose": wrap(gt_pose)}



def _no_decoder(e: Event, raw_msg: bool = False) -> Any:
    raise BagError(f"{e.kind} messages are folded into the messages they complete")
