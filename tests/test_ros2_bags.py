"""Replay of synthetic robot bags in every format (ROS 1, rosbag2 sqlite3, MCAP), and clear errors for
bags with missing or empty topics and for corrupt bags."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2

from app.config import Config
from app.ros2.errors import BagError
from app.ros2.reader import read_bag
from app.ros2.replay import ReplayCore
from app.ros2.typestore import ros1_typestore, ros2_typestore

ROOM = (-3.0, 3.0, -2.0, 2.0)  # x0, x1, y0, y1: a 6 m × 4 m room
N_BEAMS = 360


def room_ranges(px: float, py: float, yaw: float) -> np.ndarray:
    """``(N_BEAMS,)`` ranges from ``(px, py, yaw)`` to the room's walls (beam i at −π + i°)."""
    x0, x1, y0, y1 = ROOM
    a = yaw - math.pi + np.arange(N_BEAMS) * (2 * math.pi / N_BEAMS)
    c, s = np.cos(a), np.sin(a)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (x1 - px) / c, np.where(c < 0, (x0 - px) / c, np.inf))
        ty = np.where(s > 0, (y1 - py) / s, np.where(s < 0, (y0 - py) / s, np.inf))
    return np.minimum(tx, ty)


def _t(store, name):
    return store.types[name]


def _time(store, t):
    ns = int(round(t * 1e9))
    return _t(store, "builtin_interfaces/msg/Time")(sec=ns // 10**9, nanosec=ns % 10**9)


def _header(store, t, frame, ros1):
    H = _t(store, "std_msgs/msg/Header")
    return H(seq=0, stamp=_time(store, t), frame_id=frame) if ros1 else H(stamp=_time(store, t), frame_id=frame)


def _pose(store, x, y, yaw):
    P = _t(store, "geometry_msgs/msg/Pose")
    return P(position=_t(store, "geometry_msgs/msg/Point")(x=x, y=y, z=0.0),
             orientation=_t(store, "geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)))


def synthetic_messages(store, ros1: bool, *, odom_via_tf: bool = False, t0: float = 0.0, upside_down: bool = False,
                       empty_scan: bool = False):
    """(topic, msgtype, t, msg) of a robot driving 2 m along x and turning, in ROOM."""
    V = _t(store, "geometry_msgs/msg/Vector3")
    out = []
    if not upside_down:  # the LIDAR at the base's origin, from /tf_static
        tr = _t(store, "geometry_msgs/msg/TransformStamped")(
            header=_header(store, t0, "base_footprint", ros1), child_frame_id="laser",
            transform=_t(store, "geometry_msgs/msg/Transform")(
                translation=V(x=0.0, y=0.0, z=0.2), rotation=_pose(store, 0.0, 0.0, 0.0).orientation))
        out.append(("/tf_static", "tf2_msgs/msg/TFMessage", 0.0, _t(store, "tf2_msgs/msg/TFMessage")(transforms=[tr])))
    dur = 12.0
    for k in range(int(dur * 20) + 1):  # odometry at 20 Hz
        t = k / 20.0
        x, yaw = -1.0 + 2.0 * min(t / 8.0, 1.0), 0.6 * max(t - 8.0, 0.0)
        if odom_via_tf:
            tr = _t(store, "geometry_msgs/msg/TransformStamped")(
                header=_header(store, t0 + t, "odom", ros1), child_frame_id="base_footprint",
                transform=_t(store, "geometry_msgs/msg/Transform")(
                    translation=V(x=x, y=0.0, z=0.0), rotation=_pose(store, x, 0.0, yaw).orientation))
            out.append(("/tf", "tf2_msgs/msg/TFMessage", t, _t(store, "tf2_msgs/msg/TFMessage")(transforms=[tr])))
        else:
            cov = np.zeros(36)
            od = _t(store, "nav_msgs/msg/Odometry")(
                header=_header(store, t0 + t, "odom", ros1), child_frame_id="base_footprint",
                pose=_t(store, "geometry_msgs/msg/PoseWithCovariance")(pose=_pose(store, x, 0.0, yaw), covariance=cov),
                twist=_t(store, "geometry_msgs/msg/TwistWithCovariance")(
                    twist=_t(store, "geometry_msgs/msg/Twist")(linear=V(x=0.0, y=0.0, z=0.0), angular=V(x=0.0, y=0.0, z=0.0)),
                    covariance=cov))
            out.append(("/odom", "nav_msgs/msg/Odometry", t, od))
        if k % 4 == 2 and not empty_scan:  # scans at 5 Hz, between odometry samples
            ts = t
            xs = -1.0 + 2.0 * min(ts / 8.0, 1.0)
            ys = 0.6 * max(ts - 8.0, 0.0)
            r = room_ranges(xs, 0.0, ys)
            if upside_down:  # the sensor is flipped about x: beam angle a sees the world at −a
                r = np.roll(r[::-1], 1)
            scan = _t(store, "sensor_msgs/msg/LaserScan")(
                header=_header(store, t0 + ts, "laser", ros1), angle_min=-math.pi, angle_max=math.pi - math.radians(1),
                angle_increment=math.radians(1), time_increment=0.0, scan_time=0.0, range_min=0.1, range_max=12.0,
                ranges=r.astype(np.float32), intensities=np.zeros(0, np.float32))
            out.append(("/scan", "sensor_msgs/msg/LaserScan", ts + 0.01, scan))
    return out


def write_bag(path: Path, fmt: str, **kw) -> Path:
    """A synthetic bag in ``fmt``: ``ros1`` (.bag), ``sqlite3`` or ``mcap`` (rosbag2 folders)."""
    ros1 = fmt == "ros1"
    store = ros1_typestore() if ros1 else ros2_typestore()
    msgs = synthetic_messages(store, ros1, **kw)
    topics = {}
    for topic, typ, _, _ in msgs:
        topics.setdefault(topic, typ)
    if kw.get("empty_scan"):
        topics["/scan"] = "sensor_msgs/msg/LaserScan"
    t0 = kw.get("t0", 0.0)
    if ros1:
        w = Writer1(path)
        w.open()
    else:
        w = Writer2(path, version=9, storage_plugin=StoragePlugin.SQLITE3 if fmt == "sqlite3" else StoragePlugin.MCAP)
        w.open()
    conns = {t: w.add_connection(t, typ, typestore=store) for t, typ in topics.items()}
    ser = store.serialize_ros1 if ros1 else store.serialize_cdr
    for topic, typ, t, msg in msgs:
        w.write(conns[topic], int(round((t0 + t) * 1e9)), ser(msg, typ))
    w.close()
    return path


def free_area(core) -> float:
    g = core.slam.occupancy_grid(budget=10**9)
    return float(np.count_nonzero((g.data >= 0) & (g.data < 20)) * g.resolution**2)


def wall_length(core) -> float:
    g = core.slam.occupancy_grid(budget=10**9)
    return float(np.count_nonzero(g.data > 65) * g.resolution)


@pytest.mark.parametrize("fmt", ["ros1", "sqlite3", "mcap"])
def test_replay_every_format_maps_the_room(tmp_path, fmt):
    name = "room.bag" if fmt == "ros1" else "room"
    # a wall-clock ROS 1 bag (stamps around 1.7e9 s) and sim-time rosbag2 bags
    bag = read_bag(write_bag(tmp_path / name, fmt, t0=1.7e9 if fmt == "ros1" else 0.0))
    assert bag.time_offset == (1.7e9 if fmt == "ros1" else 0.0)
    assert any("no camera topic" in w for w in bag.warnings)
    core = ReplayCore(Config(), bag)
    core.run()
    assert core.state.counters.scans == 60 and core.state.counters.odom == 241
    # the room is 24 m²; the robot sees all of it from inside (walls take a cell's width)
    assert 19.0 < free_area(core) < 24.5
    T = core.T_map_base
    assert abs(T.x - 1.0) < 0.05 and abs(T.y) < 0.05 and abs(math.remainder(T.yaw - 0.6 * 4.0, 2 * math.pi)) < 0.05


def test_odometry_from_tf_when_no_odom_topic(tmp_path):
    bag = read_bag(write_bag(tmp_path / "tf", "mcap", odom_via_tf=True))
    assert bag.odom_source == "tf"
    assert any("/odom is missing" in w for w in bag.warnings)
    core = ReplayCore(Config(), bag)
    core.run()
    assert core.state.counters.odom == 241 and abs(core.T_map_base.x - 1.0) < 0.05


def test_upside_down_lidar_from_config(tmp_path):
    bag = read_bag(write_bag(tmp_path / "flip", "mcap", upside_down=True))
    good = Config()
    good.set("replay.T_base_scan", [0.0, 0.0, 0.2, math.pi, 0.0, 0.0])  # flipped about x
    core = ReplayCore(good, bag)
    assert core.extrinsic_source == "config replay.T_base_scan"
    core.run()
    wrong = ReplayCore(Config(), read_bag(tmp_path / "flip"))
    assert any("no /tf_static" in w for w in wrong.warnings)
    wrong.run()
    assert 19.0 < free_area(core) < 24.5
    T = core.T_map_base
    assert abs(T.x - 1.0) < 0.02 and abs(T.y) < 0.02
    # the room's walls are 20 m long
    assert 17.0 < wall_length(core) < 24.0
    # ignoring the flip, the mirrored scans turn against the odometry: the map's heading goes wrong
    # (the scan matcher follows the scans' own heading, so the walls themselves smear only a little)
    assert abs(math.remainder(wrong.T_map_base.yaw - 0.6 * 4.0, 2 * math.pi)) > 0.5
    assert wall_length(wrong) > 1.1 * wall_length(core)


def test_missing_scan_topic_is_named(tmp_path):
    store = ros2_typestore()
    p = tmp_path / "noscan"
    w = Writer2(p, version=9, storage_plugin=StoragePlugin.MCAP)
    w.open()
    c = w.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=store)
    for topic, typ, t, msg in synthetic_messages(store, False):
        if topic == "/odom":
            w.write(c, int(t * 1e9), store.serialize_cdr(msg, typ))
    w.close()
    with pytest.raises(BagError, match=r"no scan messages on /scan \(topic missing; topics: /odom\)"):
        read_bag(p)


def test_empty_scan_topic_is_named(tmp_path):
    with pytest.raises(BagError, match=r"no scan messages on /scan \(topic empty"):
        read_bag(write_bag(tmp_path / "empty", "mcap", empty_scan=True))


def test_no_odometry_is_named(tmp_path):
    store = ros2_typestore()
    p = tmp_path / "noodom"
    w = Writer2(p, version=9, storage_plugin=StoragePlugin.MCAP)
    w.open()
    c = w.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=store)
    for topic, typ, t, msg in synthetic_messages(store, False):
        if topic == "/scan":
            w.write(c, int(t * 1e9), store.serialize_cdr(msg, typ))
    w.close()
    with pytest.raises(BagError, match=r"no odometry: /odom is missing and there is no /tf"):
        read_bag(p)


def test_configured_topic_names(tmp_path):
    from app.ros2.reader import BagTopics

    write_bag(tmp_path / "room", "mcap")
    with pytest.raises(BagError, match="no scan messages on /base_scan"):
        read_bag(tmp_path / "room", BagTopics(scan="/base_scan"))


@pytest.mark.parametrize("kind", ["truncated_mcap", "garbage_bag", "no_metadata"])
def test_corrupt_bag_one_line_error(tmp_path, kind):
    if kind == "truncated_mcap":
        p = write_bag(tmp_path / "room", "mcap")
        f = next(p.glob("*.mcap"))
        f.write_bytes(f.read_bytes()[:3000])
    elif kind == "garbage_bag":
        p = tmp_path / "x.bag"
        p.write_bytes(b"#ROSBAG V2.0\n" + bytes(range(256)) * 10)
    else:
        p = tmp_path / "folder"
        p.mkdir()
    with pytest.raises(BagError) as e:
        read_bag(p)
    msg = str(e.value)
    assert "\n" not in msg and str(p) in msg and len(msg) < 400


def test_cli_errors_are_one_line(tmp_path):
    p = tmp_path / "x.bag"
    p.write_bytes(b"not a bag at all")
    r = subprocess.run([sys.executable, "-m", "app", "replay", str(p), "--headless", "--out", str(tmp_path / "o")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip() and "pybullet build time" not in ln]
    assert len(lines) == 1 and lines[0].startswith("ocslam replay: error:") and "x.bag" in lines[0]
    r = subprocess.run([sys.executable, "-m", "app", "replay", str(tmp_path / "missing"), "--headless"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "bag not found" in r.stderr


def test_topics_filter_and_start(tmp_path):
    p = write_bag(tmp_path / "room", "mcap")
    with pytest.raises(BagError, match="no odometry"):
        read_bag(p, only={"/scan"})  # --topics /scan: the odometry is left out
    assert read_bag(p, only={"/scan", "/odom"}).topic_counts["/scan"] == 60


def test_headless_replay_writes_a_run_directory(tmp_path):
    import json

    from app.cli import main

    p = write_bag(tmp_path / "room", "sqlite3")
    out = tmp_path / "run"
    assert main(["replay", str(p), "--headless", "--quiet", "--start", "4", "--out", str(out)]) == 0
    for f in ("config.yaml", "summary.json", "map.yaml", "map.pgm", "objects.json", "trajectory_slam.tum",
              "trajectory_odom.tum"):
        assert (out / f).is_file(), f
    s = json.loads((out / "summary.json").read_text())
    assert s["end_reason"] == "end of bag" and s["counters"]["scans"] == 40  # --start 4: the last 8 s
    assert s["lidar_extrinsic"] == "/tf_static" and s["bag_time_s"] == pytest.approx(8.0, abs=0.1)
    lines = (out / "trajectory_slam.tum").read_text().splitlines()
    assert len(lines) == 41 and float(lines[1].split()[0]) == pytest.approx(4.1, abs=1e-6)
