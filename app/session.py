"""Run directories ("sessions"): everything a run produced, written atomically, and loaded back.

A run directory holds::

    config.yaml          the config used (``ocslam run --config`` accepts it)
    summary.json         metrics (headless: the run's summary)
    map.yaml, map.pgm    the SLAM grid in map_server / Nav2 format
    objects.json         the object map, one vision_msgs/Detection3D-shaped entry per object
    trajectory_slam.tum  the SLAM trajectory (TUM: stamp x y z qx qy qz qw)
    trajectory_odom.tum  the raw odometry
    scene.viser          a viser recording of the run (robot along its path over the final map and objects),
    scene.html           the same, as a self-contained HTML page playable offline
    state.npz            SLAM keyframes/graph + tracker + sim state, so "Load session" can continue mapping
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from app.config import atomic_write_bytes, atomic_write_text
from app.ocslam.messages import TrackedObject
from app.ocslam.se2 import Pose2

if TYPE_CHECKING:
    from app.pipeline import Pipeline

log = logging.getLogger(__name__)

SESSION_VERSION = 1


def _quat(yaw: float) -> dict[str, float]:
    return {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}


def object_to_detection3d(o: TrackedObject, stamp: float, frame_id: str) -> dict[str, Any]:
    """One object as vision_msgs/Detection3D (field names one-to-one), plus OCSLAM's tracking fields."""
    z = o.size_z / 2 if o.size_z > 0 else 0.0
    pose = {"position": {"x": o.pose.x, "y": o.pose.y, "z": z}, "orientation": _quat(o.pose.yaw)}
    return {
        "header": {"stamp": stamp, "frame_id": frame_id},
        "id": str(o.id),
        "results": [{"hypothesis": {"class_id": o.label, "score": round(float(o.presence), 4)}, "pose": {"pose": pose}}],
        "bbox": {"center": pose, "size": {"x": o.size_x, "y": o.size_y, "z": o.size_z}},
        "presence": round(float(o.presence), 4),
        "detection_confidence": round(float(o.detection_confidence), 4),
        "frames_seen": int(o.frames_seen),
        "source": o.source,
    }


def objects_json(pipe: "Pipeline", *, all_objects: bool = False) -> dict[str, Any]:
    """The object map in the map frame (objects at presence ≥ threshold unless ``all_objects``)."""
    thr = pipe.cfg.consciousness.presence_threshold
    out = []
    for o in pipe.objects_in_map():
        if not all_objects and o.presence < thr:
            continue
        out.append(object_to_detection3d(o, pipe.time, "map"))
    return {"frame_id": "map", "presence_threshold": thr, "stamp": pipe.time, "detections": out}


def tum_lines(stamps: np.ndarray, poses: np.ndarray) -> str:
    """TUM trajectory text: ``stamp x y z qx qy qz qw`` per line."""
    lines = ["# timestamp tx ty tz qx qy qz qw"]
    for t, (x, y, yaw) in zip(np.asarray(stamps), np.asarray(poses).reshape(-1, 3)):
        lines.append(f"{t:.6f} {x:.6f} {y:.6f} 0 0 0 {math.sin(yaw / 2):.9f} {math.cos(yaw / 2):.9f}")
    return "\n".join(lines) + "\n"


def _npz_bytes(**arrays: Any) -> bytes:
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return buf.getvalue()


def pack_state(tree: Any) -> dict[str, np.ndarray]:
    """A nested state (dicts, lists, scalars, strings, numpy arrays) → arrays for ``np.savez``:
    every array is stored under its own key and replaced by ``{"__array__": key}`` in a JSON tree
    kept under ``"__tree__"``. Loads without pickle."""
    arrays: dict[str, np.ndarray] = {}

    def walk(x: Any) -> Any:
        if isinstance(x, np.ndarray):
            key = f"a{len(arrays)}"
            arrays[key] = x
            return {"__array__": key}
        if isinstance(x, dict):
            return {str(k): walk(v) for k, v in x.items()}
        if isinstance(x, (list, tuple)):
            return [walk(v) for v in x]
        if isinstance(x, np.generic):
            return x.item()
        if isinstance(x, Pose2):
            return [x.x, x.y, x.yaw]
        return x

    tree_json = json.dumps(walk(tree))
    arrays["__tree__"] = np.array(tree_json)
    return arrays


def unpack_state(arrays: dict[str, np.ndarray]) -> Any:
    """Inverse of :func:`pack_state`."""
    tree = json.loads(str(arrays["__tree__"]))

    def walk(x: Any) -> Any:
        if isinstance(x, dict):
            if set(x) == {"__array__"}:
                return np.asarray(arrays[x["__array__"]])
            return {k: walk(v) for k, v in x.items()}
        if isinstance(x, list):
            return [walk(v) for v in x]
        return x

    return walk(tree)


def _json_default(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Pose2):
        return [o.x, o.y, o.yaw]
    return str(o)


def save_session(pipe: "Pipeline", out: str | Path, *, summary: dict[str, Any] | None = None, server: Any = None) -> Path:
    """Write the run directory ``out`` (every file atomically). Returns ``out``."""
    from app.ocslam.mapio import save_map

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    pipe.cfg.save(out / "config.yaml")
    summary = summary if summary is not None else pipe.summary()
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=2, default=_json_default))
    grid = pipe.slam.occupancy_grid()
    if grid.width and grid.height:
        save_map(grid, out / "map.yaml")
    atomic_write_text(out / "objects.json", json.dumps(objects_json(pipe), indent=2, default=_json_default))
    stamps, traj = pipe.slam.trajectory()
    atomic_write_text(out / "trajectory_slam.tum", tum_lines(stamps, traj))
    if pipe.truth_log:
        s = np.array([t for t, _, _ in pipe.truth_log])
        o = np.array([p.as_array() for _, _, p in pipe.truth_log])
        atomic_write_text(out / "trajectory_odom.tum", tum_lines(s, o))
    atomic_write_bytes(out / "state.npz", _npz_bytes(**pack_state(session_state(pipe))))
    try:
        write_recording(pipe, out)
    except Exception as e:  # the recording is a convenience; never lose the rest for it
        log.warning("scene recording not written: %s", e)
    return out


def session_state(pipe: "Pipeline") -> dict[str, Any]:
    return {
        "version": SESSION_VERSION,
        "sim_time": pipe.time,
        "T_world_base_true": pipe.sim.true_pose().as_array(),
        "T_odom_base": pipe.odometry.T_odom_base.as_array(),
        "odometry_distance": pipe.odometry.distance_m,
        "slam": pipe.slam.state_dict(),
        "consciousness": pipe.consciousness.state_dict(),
    }


def load_session(pipe: "Pipeline", path: str | Path) -> None:
    """Restore map, pose graph, objects and the robot's state from a run directory, to continue mapping."""
    from app.ocslam.consciousness import Consciousness
    from app.ocslam.slam import Slam

    path = Path(path)
    f = path / "state.npz"
    if not f.is_file():
        raise FileNotFoundError(f"{path} is not a session directory (no state.npz); save one with 'Save session'")
    try:
        with np.load(f, allow_pickle=False) as z:
            state = unpack_state({k: z[k] for k in z.files})
    except Exception as e:
        raise ValueError(f"{f}: unreadable session state ({e})") from None
    if int(state.get("version", 0)) != SESSION_VERSION:
        raise ValueError(f"{f}: session version {state.get('version')} is not {SESSION_VERSION}")
    slam = Slam.from_state_dict(pipe.cfg.slam, state["slam"])
    cons = Consciousness.from_state_dict(state["consciousness"], pipe.cfg.consciousness, pipe.camera_model)
    pipe.sim.set_robot_pose(Pose2.from_array(state["T_world_base_true"]))
    pipe.restart_clock(float(state["sim_time"]))
    pipe.slam = slam
    pipe.consciousness = cons
    pipe._slam_corrections = slam.correction_count
    pipe.restart_odometry(Pose2.from_array(state["T_odom_base"]))
    pipe.odometry.distance_m = float(state.get("odometry_distance", 0.0))
    pipe.scans.clear()
    pipe.last_scan = None
    pipe.stop_autonomy("session loaded")


def recording_html(scene_bytes: bytes, dark_mode: bool = False) -> str:
    """A self-contained HTML player for ``.viser`` bytes (what viser's ``StateSerializer.as_html`` does,
    without serialising twice)."""
    import base64

    import viser

    client = (Path(viser.__file__).parent / "client" / "build" / "index.html").read_text(encoding="utf-8")
    b64 = base64.b64encode(scene_bytes).decode("ascii")
    inject = (
        f'<script>window.__VISER_EMBED_DATA__="{b64}";'
        f"window.__VISER_EMBED_CONFIG__={{darkMode:{'true' if dark_mode else 'false'}}};</script>"
    )
    i = client.index("</head>")
    return client[:i] + inject + client[i:]


def write_recording(pipe: "Pipeline", out: Path, *, max_frames: int = 400) -> None:
    """A `.viser` recording (and a self-contained HTML player): the final map, objects and graph, with the
    robot replaying its SLAM trajectory."""
    from app.ui.scene import SceneLayers
    from app.ui.security import create_server

    with contextlib.redirect_stdout(io.StringIO()):  # viser prints a banner even with verbose=False
        server, _ = create_server("127.0.0.1", 0)
    try:
        layers = SceneLayers(server, pipe)
        for key in ("truth", "graph"):
            layers.set_visible(key, key == "graph")
        layers.update(with_map=True)
        rec = server.get_scene_serializer()
        stamps, traj = pipe.slam.trajectory()
        if len(traj) > 1:
            idx = np.linspace(0, len(traj) - 1, min(max_frames, len(traj))).astype(int)
            dt = float(np.median(np.diff(stamps[idx]))) if len(idx) > 1 else 0.1
            for i in idx:
                T = Pose2.from_array(traj[i])
                layers._set_pose(layers.robot_root, T)
                rec.insert_sleep(min(max(dt / 4.0, 0.02), 0.25))  # 4× faster than real time
        data = rec.serialize()
        atomic_write_bytes(out / "scene.viser", data)
        atomic_write_text(out / "scene.html", recording_html(data))
    finally:
        with contextlib.redirect_stdout(io.StringIO()):
            server.stop()
