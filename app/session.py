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

**Written as a unit** (:func:`write_run_dir`): every file goes into a temporary sibling directory
``.NAME.tmp-*``, which is renamed to ``NAME`` when complete; an existing ``NAME`` is kept as
``NAME.prev`` until that rename has succeeded, then removed, so a run directory is always either the
old one or the new one, never a mix, and files the new run does not produce are not left beside it.
An existing directory is only replaced if it is a run directory (empty, or nothing but files and a
``bag`` folder, among them ``summary.json`` or ``state.npz``); anything else is refused with
:class:`SessionError`.

**Validated on load**: ``app.session_load`` (:func:`~app.session_load.read_session`,
:func:`~app.session_load.load_session`) reads a run directory back and checks it before anything of the
running pipeline changes.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import math
import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from app.config import atomic_write_bytes, atomic_write_text
from app.ocslam.messages import TrackedObject
from app.ocslam.se2 import Pose2

if TYPE_CHECKING:
    from app.pipeline import Pipeline

log = logging.getLogger(__name__)

SESSION_VERSION = 2
#: versions :func:`app.session_load.read_session` accepts (1: before the world name was stored)
READABLE_VERSIONS = (1, 2)

#: the files a run directory holds (see the module docstring)
RUN_FILES = frozenset({
    "config.yaml", "summary.json", "map.yaml", "map.pgm", "objects.json", "trajectory_slam.tum",
    "trajectory_odom.tum", "scene.viser", "scene.html", "state.npz",
})
#: sub-folders a run directory may hold (a rosbag2 recording, docs/ros2.md)
RUN_DIRS = frozenset({"bag"})
#: files only runs write: a directory holding one of them is a run directory
RUN_MARKERS = ("summary.json", "state.npz")

_UMASK = os.umask(0)
os.umask(_UMASK)


class SessionError(ValueError):
    """A run directory cannot be written where asked, or a saved session is missing, corrupt or
    inconsistent. The message names the directory and the problem."""


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


def objects_json(pipe: Pipeline, *, all_objects: bool = False) -> dict[str, Any]:
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


# ----------------------------------------------------------------------------------------------
# Run directories written as a unit
# ----------------------------------------------------------------------------------------------


def _nearest_existing(p: Path) -> Path:
    q = p
    while not q.exists() and q != q.parent:
        q = q.parent
    return q


def is_run_dir(path: Path) -> bool:
    """True if ``path`` may be replaced by a new run directory: empty, or only regular files (and a ``bag``
    folder) that are all run files or include ``summary.json``/``state.npz``."""
    try:
        entries = list(os.scandir(path))
    except OSError:
        return False
    if not entries:
        return True
    if any(not e.is_file(follow_symlinks=False) and not (e.name in RUN_DIRS and e.is_dir(follow_symlinks=False))
           for e in entries):
        return False
    names = {e.name for e in entries if e.name not in RUN_DIRS}
    return names <= RUN_FILES or any(m in names for m in RUN_MARKERS)


def _probe_writable(base: Path, out: Path, what: str) -> None:
    """Create and remove an empty temporary folder in ``base`` (``os.access`` says yes to root even on a
    read-only mount); :class:`SessionError` if that fails."""
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".ocslam-probe-", dir=base))
    except OSError as e:
        raise SessionError(f"{what} {out}: {base} is not writable ({e.strerror or e})") from None


def check_run_dir(out: str | os.PathLike[str], *, what: str = "--out") -> Path:
    """Check that a run directory can be written at ``out`` without writing anything there.

    Raises :class:`SessionError` if ``out`` is a file, lies under a file, cannot be written (its nearest
    existing parent is not a writable directory), or is an existing directory that is not a run
    directory (:func:`is_run_dir`). Returns ``out`` as an absolute path."""
    out = Path(os.path.abspath(Path(out).expanduser()))
    if out.name in ("", ".", "..") or out == out.parent:
        raise SessionError(f"{what} {out}: not a usable run directory name")
    if out.exists() or out.is_symlink():
        if not out.is_dir():
            raise SessionError(f"{what} {out} is a file, not a directory")
        if not is_run_dir(out):
            raise SessionError(
                f"{what} {out} exists and is not a run directory (it holds sub-folders or files a run does not write); "
                "choose another directory"
            )
    base = _nearest_existing(out.parent)
    if not base.is_dir():
        raise SessionError(f"{what} {out}: {base} is a file, not a directory")
    _probe_writable(base, out, what)
    prev = out.with_name(out.name + ".prev")
    if prev.exists() and not (prev.is_dir() and is_run_dir(prev)):
        raise SessionError(f"{what} {out}: {prev} exists and is not a run directory; move it away first")
    return out


def check_out_file(out: str | os.PathLike[str], *, what: str = "--out") -> Path:
    """Check that the file ``out`` can be written (atomically, beside itself) without writing anything:
    :class:`SessionError` if it is a directory, lies under a file, or its nearest existing parent is not
    writable. Returns ``out`` as an absolute path."""
    out = Path(os.path.abspath(Path(out).expanduser()))
    if out.is_dir():
        raise SessionError(f"{what} {out} is a directory, not a file")
    base = _nearest_existing(out.parent)
    if not base.is_dir():
        raise SessionError(f"{what} {out}: {base} is a file, not a directory")
    _probe_writable(base, out, what)
    return out


def _clean_stale_tmp(out: Path) -> None:
    """Remove ``.NAME.tmp-PID-*`` siblings left by runs that were killed (their process is gone)."""
    try:
        siblings = list(out.parent.glob(f".{out.name}.tmp-*"))
    except OSError:
        return
    for d in siblings:
        try:
            pid = int(d.name[len(f".{out.name}.tmp-"):].split("-")[0])
        except ValueError:
            continue
        if pid == os.getpid():
            continue
        try:
            os.kill(pid, 0)
            continue  # still running: its own write in progress
        except ProcessLookupError:
            pass
        except PermissionError:
            continue
        shutil.rmtree(d, ignore_errors=True)


def _fsync_dir(d: Path) -> None:
    try:
        fd = os.open(d, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_run_dir(out: str | os.PathLike[str], write: Callable[[Path], Any], *, what: str = "--out") -> Path:
    """Write a whole run directory as a unit: ``write(tmp)`` fills a fresh temporary sibling directory,
    which then replaces ``out`` (the previous ``out`` is kept as ``out.prev`` until the rename succeeded).

    If ``write`` raises (or the process dies), ``out`` is untouched and the temporary directory is removed
    (by the next write to ``out`` after a kill). Every file gets the same mode (``0666 & ~umask``).
    Returns ``out``."""
    out = check_run_dir(out, what=what)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise SessionError(f"{what} {out}: cannot create {out.parent}: {e.strerror or e}") from None
    _clean_stale_tmp(out)
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-{os.getpid()}-", dir=out.parent))
    except OSError as e:
        raise SessionError(f"{what} {out}: cannot write in {out.parent}: {e.strerror or e}") from None
    prev = out.with_name(out.name + ".prev")
    try:
        os.chmod(tmp, 0o777 & ~_UMASK)
        write(tmp)
        for f in tmp.iterdir():
            if f.is_file():
                os.chmod(f, 0o666 & ~_UMASK)
        _fsync_dir(tmp)
        if out.exists():
            if prev.exists():
                shutil.rmtree(prev)  # a run directory left by an interrupted replace (checked above)
            os.replace(out, prev)
        os.replace(tmp, out)
        _fsync_dir(out.parent)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        if prev.exists() and not out.exists():
            os.replace(prev, out)  # put the previous run directory back
        raise
    shutil.rmtree(prev, ignore_errors=True)
    return out


def summary_json(summary: dict[str, Any]) -> str:
    """``summary`` as strict JSON text: NaN and ±inf become ``null`` (never a bare ``NaN``)."""
    return json.dumps(_finite_or_none(summary), indent=2, default=_json_default, allow_nan=False) + "\n"


def _finite_or_none(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _finite_or_none(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_finite_or_none(v) for v in x]
    if isinstance(x, np.ndarray):
        return _finite_or_none(x.tolist())
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, Pose2):
        return _finite_or_none([x.x, x.y, x.yaw])
    return x


def write_session_files(pipe: Pipeline, out: Path, *, summary: dict[str, Any] | None = None) -> None:
    """Write every file of a run directory into the existing directory ``out`` (see :func:`save_session`)."""
    from app.ocslam.mapio import save_map

    pipe.cfg.save(out / "config.yaml")
    summary = summary if summary is not None else pipe.summary()
    atomic_write_text(out / "summary.json", summary_json(summary))
    grid = pipe.slam.occupancy_grid()
    if grid.width and grid.height:
        save_map(grid, out / "map.yaml")
    atomic_write_text(out / "objects.json", json.dumps(_finite_or_none(objects_json(pipe)), indent=2, default=_json_default))
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


def save_session(pipe: Pipeline, out: str | Path, *, summary: dict[str, Any] | None = None, server: Any = None,
                 extra: Callable[[Path], Any] | None = None) -> Path:
    """Write the run directory ``out`` as a unit (:func:`write_run_dir`); ``extra(tmp)`` may add more to it
    (e.g. a bag) before it is renamed into place. Returns ``out`` (absolute). :class:`SessionError` if
    ``out`` cannot be a run directory (nothing is written then)."""

    def write(d: Path) -> None:
        write_session_files(pipe, d, summary=summary)
        if extra is not None:
            extra(d)

    return write_run_dir(out, write)


def session_state(pipe: Pipeline) -> dict[str, Any]:
    return {
        "version": SESSION_VERSION,
        "world": pipe.world.name,
        "sim_time": pipe.time,
        "T_world_base_true": pipe.sim.true_pose().as_array(),
        "T_odom_base": pipe.odometry.T_odom_base.as_array(),
        "odometry_distance": pipe.odometry.distance_m,
        "slam": pipe.slam.state_dict(),
        "consciousness": pipe.consciousness.state_dict(),
    }


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


def recording_bytes(pipe: Pipeline, *, max_frames: int = 400) -> bytes:
    """A `.viser` recording: the final map, objects and graph, with the robot replaying its SLAM trajectory."""
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
        return rec.serialize()
    finally:
        with contextlib.redirect_stdout(io.StringIO()):
            server.stop()


def write_recording(pipe: Pipeline, out: Path, *, max_frames: int = 400) -> None:
    """``out/scene.viser`` and ``out/scene.html`` (a self-contained player), each written atomically."""
    data = recording_bytes(pipe, max_frames=max_frames)
    atomic_write_bytes(out / "scene.viser", data)
    atomic_write_text(out / "scene.html", recording_html(data))
