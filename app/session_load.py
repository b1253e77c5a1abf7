"""Loading a run directory ("session") back: read and validated first, then restored into a pipeline.

**Validated on load** (:func:`read_session`): ``config.yaml`` and ``state.npz`` must exist and parse;
the version, the world name, the array shapes, and the finiteness of every pose, stamp and size are
checked before anything of the running pipeline changes (:func:`load_session`). The format and its
writing are ``app.session``'s.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from app.ocslam.se2 import Pose2
from app.session import READABLE_VERSIONS, SessionError, unpack_state

if TYPE_CHECKING:
    from app.pipeline import Pipeline


@dataclass
class SessionData:
    """A validated run directory: its config and its unpacked ``state.npz``."""

    path: Path
    cfg: Any  # app.config.Config
    state: dict[str, Any]

    @property
    def world(self) -> str | None:
        w = self.state.get("world")
        return str(w) if w is not None else None

    def slam(self, slam_cfg: Any = None) -> Any:
        """The SLAM back end rebuilt from the state (checked: finite keyframe poses and trajectory)."""
        return restore_slam(self.path, slam_cfg if slam_cfg is not None else self.cfg.slam, self.state)

    def check(self) -> SessionData:
        """Rebuild (and so check) the SLAM and object states too; :class:`SessionError` on any problem."""
        self.slam()
        self.consciousness()
        return self

    def consciousness(self, cons_cfg: Any = None, camera_model: Any = None) -> Any:
        """The object tracker rebuilt from the state (checked: finite poses, sizes and presences)."""
        if camera_model is None:
            from app.pipeline import build_camera_model
            from app.sim.robot_model import RobotModel

            camera_model = build_camera_model(self.cfg, RobotModel.load())
        return restore_consciousness(self.path, cons_cfg if cons_cfg is not None else self.cfg.consciousness,
                                     camera_model, self.state)


def _bad(path: Path, msg: str) -> SessionError:
    return SessionError(f"{path}: corrupt session: {msg}")


def _finite_array(path: Path, state: dict, key: str, shape: tuple[Any, ...], *, where: str = "") -> np.ndarray:
    name = f"{where}{key}"
    if key not in state:
        raise _bad(path, f"'{name}' is missing")
    try:
        a = np.asarray(state[key], dtype=np.float64)
    except (TypeError, ValueError):
        raise _bad(path, f"'{name}' is not numeric") from None
    if shape and shape[-1] is Ellipsis:  # (N, ...): only the leading dimension is fixed by the format
        shape = shape[:-1]
        ok = a.ndim >= len(shape) and all(n is None or a.shape[i] == n for i, n in enumerate(shape))
    else:
        ok = a.ndim == len(shape) and all(n is None or a.shape[i] == n for i, n in enumerate(shape))
    if not ok:
        want = "(" + ", ".join("N" if n is None else str(n) for n in shape) + ("," if len(shape) == 1 else "") + ")"
        raise _bad(path, f"'{name}' has shape {a.shape}, expected {want}")
    if not np.isfinite(a).all():
        raise _bad(path, f"'{name}' has non-finite values (NaN or inf)")
    return a


def _finite_scalar(path: Path, state: dict, key: str, *, nonneg: bool = False, default: Any = None) -> float:
    v = state.get(key, default)
    if isinstance(v, bool) or not isinstance(v, (int, float, np.number)) or not math.isfinite(float(v)):
        raise _bad(path, f"'{key}' must be a finite number, got {v!r}")
    if nonneg and float(v) < 0:
        raise _bad(path, f"'{key}' must be ≥ 0, got {v!r}")
    return float(v)


def _check_slam_arrays(path: Path, d: Any) -> None:
    """Shapes and finiteness of the SLAM state's arrays that exist (the back end checks the rest)."""
    if not isinstance(d, dict):
        raise _bad(path, "'slam' is not a mapping")
    w = "slam."
    checks = {"T_base_scan": (3,), "kf_poses": (None, 3), "kf_stamps": (None,), "kf_points": (None, 2),
              "kf_ends": (None, 2), "kf_sensor": (None, 2), "edges_z": (None, 3), "edges_info": (None, ...),
              "traj_stamps": (None,), "traj_rel": (None, 3), "traj_odom": (None, 3)}
    arrs = {k: _finite_array(path, d, k, shp, where=w) for k, shp in checks.items() if k in d}
    n_kf = len(arrs["kf_poses"]) if "kf_poses" in arrs else None

    def rows(k: str) -> int:
        a = np.asarray(d[k])
        return int(a.shape[0]) if a.ndim else -1

    for a, b in (("kf_poses", "kf_stamps"), ("kf_poses", "kf_npoints"), ("kf_poses", "kf_nends"), ("kf_poses", "kf_sensor"),
                 ("kf_ends", "kf_hit"), ("edges_ij", "edges_z"), ("edges_z", "edges_info"), ("traj_stamps", "traj_anchor"),
                 ("traj_stamps", "traj_rel"), ("traj_stamps", "traj_odom")):
        if a in d and b in d and rows(a) != rows(b):
            raise _bad(path, f"'{w}{a}' ({rows(a)} rows) and '{w}{b}' ({rows(b)} rows) differ in length")
    for count, data in (("kf_npoints", "kf_points"), ("kf_nends", "kf_ends")):
        if count in d and data in d:
            c = np.asarray(d[count]).reshape(-1)
            ok = c.size == 0 or (np.issubdtype(c.dtype, np.integer) and c.min() >= 0)
            if not ok or int(c.sum()) != rows(data):
                raise _bad(path, f"'{w}{count}' does not add up to the {rows(data)} rows of '{w}{data}'")
    if n_kf is not None:
        for key, cols in (("edges_ij", 2), ("traj_anchor", 1)):
            if key in d:
                a = np.asarray(d[key])
                if a.size and (not np.issubdtype(a.dtype, np.integer) or a.min() < 0 or a.max() >= n_kf):
                    raise _bad(path, f"'{w}{key}' refers to keyframes outside 0…{n_kf - 1}")
                if cols == 2 and a.size and (a.ndim != 2 or a.shape[1] != 2):
                    raise _bad(path, f"'{w}{key}' has shape {a.shape}, expected (N, 2)")


def restore_slam(path: Path, slam_cfg: Any, state: dict[str, Any]) -> Any:
    from app.ocslam.slam import Slam

    _check_slam_arrays(path, state.get("slam"))
    try:
        slam = Slam.from_state_dict(slam_cfg, state["slam"])
    except Exception as e:
        raise _bad(path, f"SLAM state: {type(e).__name__}: {e}") from None
    try:
        nodes = np.asarray(slam.pose_graph().nodes, dtype=np.float64)
        _, traj = slam.trajectory()
        traj = np.asarray(traj, dtype=np.float64)
    except Exception as e:
        raise _bad(path, f"SLAM state: {type(e).__name__}: {e}") from None
    if not np.isfinite(nodes).all():
        raise _bad(path, "a keyframe pose is not finite")
    if not np.isfinite(traj).all():
        raise _bad(path, "a trajectory pose is not finite")
    return slam


def restore_consciousness(path: Path, cons_cfg: Any, camera_model: Any, state: dict[str, Any]) -> Any:
    from app.ocslam.consciousness import Consciousness

    if not isinstance(state.get("consciousness"), dict):
        raise _bad(path, "'consciousness' is missing or not a mapping")
    try:
        cons = Consciousness.from_state_dict(state["consciousness"], cons_cfg, camera_model)
        objects = list(cons.objects)
    except Exception as e:
        raise _bad(path, f"object state: {type(e).__name__}: {e}") from None
    for o in objects:
        vals = {"x": o.pose.x, "y": o.pose.y, "yaw": o.pose.yaw, "size_x": o.size_x, "size_y": o.size_y,
                "size_z": o.size_z, "presence": o.presence}
        for k, v in vals.items():
            if not math.isfinite(float(v)):
                raise _bad(path, f"object {o.id} ({o.label}): {k} is not finite")
        if min(o.size_x, o.size_y, o.size_z) < 0:
            raise _bad(path, f"object {o.id} ({o.label}): negative size")
        if not 0.0 <= o.presence <= 1.0:
            raise _bad(path, f"object {o.id} ({o.label}): presence {o.presence} is outside [0, 1]")
    return cons


def read_session(path: str | os.PathLike[str], *, need_config: bool = True) -> SessionData:
    """Read and check a run directory's ``config.yaml`` and ``state.npz`` (version, required fields,
    finite sim time and poses). :class:`SessionError` (or ``ConfigError`` for a bad config) otherwise.
    The SLAM and object states are checked when rebuilt (:meth:`SessionData.slam`/``consciousness``)."""
    from app.config import Config

    path = Path(path)
    if not path.is_dir():
        prev = path.with_name(path.name + ".prev")
        hint = f" (an interrupted save left the previous session at {prev})" if prev.is_dir() else ""
        if path.exists():
            raise SessionError(f"{path} is a file, not a session directory")
        raise SessionError(f"{path}: no such session directory{hint}")
    f = path / "state.npz"
    if not f.is_file():
        raise SessionError(f"{path} is not a session directory (no state.npz); save one with 'Save session' or a headless run")
    c = path / "config.yaml"
    cfg = None
    if need_config:
        if not c.is_file():
            raise SessionError(f"{path}: no config.yaml (a run directory holds the config it was made with)")
        cfg = Config.load(c)
    try:
        with np.load(f, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        state = unpack_state(arrays)
    except Exception as e:  # BadZipFile, zlib/EOF errors, missing arrays, bad JSON
        raise SessionError(f"{f}: unreadable session state ({type(e).__name__}: {e})") from None
    if not isinstance(state, dict):
        raise _bad(path, "the state is not a mapping")
    version = state.get("version")
    if isinstance(version, bool) or not isinstance(version, int) or version not in READABLE_VERSIONS:
        raise SessionError(f"{f}: session version {version!r} is not one this OCSLAM reads ({', '.join(map(str, READABLE_VERSIONS))})")
    if version >= 2 and not (isinstance(state.get("world"), str) and state["world"]):
        raise _bad(path, "'world' (the world's name) is missing")
    _finite_scalar(path, state, "sim_time", nonneg=True)
    _finite_scalar(path, state, "odometry_distance", nonneg=True, default=0.0)
    _finite_array(path, state, "T_world_base_true", (3,))
    _finite_array(path, state, "T_odom_base", (3,))
    for k in ("slam", "consciousness"):
        if not isinstance(state.get(k), dict):
            raise _bad(path, f"'{k}' is missing or not a mapping")
    return SessionData(path, cfg, state)


def load_session(pipe: Pipeline, path: str | Path) -> None:
    """Restore map, pose graph, objects and the robot's state from a run directory, to continue mapping.

    Everything is read and checked first (:func:`read_session`, world name, rebuilt SLAM and objects); on
    any problem :class:`SessionError` is raised and the running pipeline is unchanged."""
    data = read_session(path)
    if data.world is not None and data.world != pipe.world.name:
        raise SessionError(f"{data.path}: the session was recorded in world {data.world!r}, not in the loaded world "
                           f"{pipe.world.name!r}; load that world first")
    slam = data.slam(pipe.cfg.slam)
    cons = data.consciousness(pipe.cfg.consciousness, pipe.camera_model)
    state = data.state
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
