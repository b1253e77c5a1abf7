"""The SLAM's side of a ``--reuse-detections`` replay, kept so that the next replay runs only the object map.

With ``--reuse-detections`` the consciousness is fed the recorded ``/yolo_boxes``, and everything else it
is handed (the scan nearest each image moved to its instant, ``T_map_base`` at the image's stamp, the
SLAM keyframe and its pose, the occupancy grid, whether the robot moved, and the SLAM's corrections
after a loop closure) depends only on the bag, the SLAM's and the replay's settings and a few
consciousness settings (``mode``, ``sync_tolerance_s``, ``corner_check``): :data:`TRACE_FIXED`. Nothing
the consciousness does feeds back into the SLAM. So the first replay records those calls
(:class:`RecordingConsciousness` stands in front of the real consciousness and forwards every call),
and a later replay with the same :func:`trace_key` (any other consciousness constant may differ) feeds
them, in the same order and with the same arguments, to a fresh consciousness
(:class:`TraceReplay`): the same object map as the full replay, without reading the bag or running the
SLAM. The trace also holds what the run directory and the summary need (final grid, trajectories,
ground truth).

API for trials (issue 16): ``trace = load_trace(path)`` (or :func:`build_trace`), then
``TraceReplay(trace, cfg).run()`` and ``.objects_in_map()`` / ``.object_report()``; :func:`trace_can_run`
says whether ``cfg`` may use a trace.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import pickle
import time
import zlib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from app.ocslam.messages import Detections, LaserScan, OccupancyGrid, TrackedObject
from app.ocslam.se2 import Pose2

#: bump when the trace's content or meaning changes
TRACE_VERSION = 1
#: consciousness settings that change what the consciousness is handed (a trace is built with them)
TRACE_FIXED = ("mode", "sync_tolerance_s", "corner_check")
#: source files whose code decides what a trace holds (part of the key)
_CODE = ("app/ocslam/slam", "app/ocslam/sync.py", "app/ocslam/se2.py", "app/ros2")


def default_cache_dir() -> Path | None:
    """``$OCSLAM_CACHE_DIR/replay`` when the user set that variable, else None: a replay never writes a
    cache the user did not choose (``--cache-dir`` chooses one per command)."""
    if os.environ.get("OCSLAM_CACHE_DIR"):
        return Path(os.environ["OCSLAM_CACHE_DIR"]) / "replay"
    return None


def _code_digest() -> str:
    root = Path(__file__).resolve().parents[2]
    h = hashlib.sha256()
    for rel in _CODE:
        p = root / rel
        files = sorted(p.rglob("*.py")) if p.is_dir() else [p]
        for f in files:
            h.update(str(f.relative_to(root)).encode())
            h.update(f.read_bytes())
    return h.hexdigest()


def _fields(section: Any) -> dict[str, Any]:
    return dataclasses.asdict(section) if dataclasses.is_dataclass(section) else dict(vars(section))


def trace_key(bag_path: str | Path, cfg: Any, start: float = 0.0, topics: list[str] | None = None) -> str:
    """What a trace depends on: the bag's files (path, size, mtime), the SLAM's and the replay's settings,
    :data:`TRACE_FIXED`, ``--start``/``--topics`` and the code that builds it."""
    p = Path(bag_path).resolve()
    files = sorted(p.rglob("*")) if p.is_dir() else [p]
    stats = [(str(f), f.stat().st_size, f.stat().st_mtime_ns) for f in files if f.is_file()]
    replay = {k: v for k, v in _fields(cfg.replay).items() if k != "snapshot_period_s"}
    doc = {
        "version": TRACE_VERSION,
        "bag": stats,
        "slam": _fields(cfg.slam),
        "replay": replay,
        "consciousness": {k: getattr(cfg.consciousness, k) for k in TRACE_FIXED},
        "start": float(start),
        "topics": sorted(topics) if topics else None,
        "code": _code_digest(),
    }
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()[:32]


@dataclass
class FuseInput:
    """One ``Consciousness.update`` call's arguments; ``grid`` indexes :attr:`SlamTrace.grids`."""

    detections: Detections
    scan: LaserScan
    T_frame_base: Pose2
    stamp: float
    keyframe: tuple[int, Pose2] | None
    robot_moved: bool | None
    grid: int | None


@dataclass
class Correction:
    """A SLAM correction: ``(K, 3)`` every keyframe's corrected ``T_map_kf``."""

    keyframe_poses: np.ndarray

    def pose(self, k: int) -> Pose2:
        if k < 0:
            raise IndexError(k)
        return Pose2.from_array(self.keyframe_poses[k])


@dataclass
class _Grid:
    """An occupancy grid, zlib-compressed (exact: every cell as it was)."""

    resolution: float
    origin: Pose2
    shape: tuple[int, int]
    blob: bytes
    stamp: float
    frame_id: str

    @classmethod
    def of(cls, g: OccupancyGrid) -> _Grid:
        d = np.ascontiguousarray(g.data, dtype=np.int8)
        return cls(float(g.resolution), g.origin, (int(d.shape[0]), int(d.shape[1])), zlib.compress(d.tobytes(), 1),
                   float(g.stamp), str(g.frame_id))

    def grid(self) -> OccupancyGrid:
        d = np.frombuffer(zlib.decompress(self.blob), dtype=np.int8).reshape(self.shape).copy()
        return OccupancyGrid(self.resolution, self.origin, d, self.stamp, self.frame_id)


@dataclass
class SlamTrace:
    """Everything a consciousness-only replay of one bag needs (picklable)."""

    key: str
    events: list[FuseInput | Correction]
    grids: list[_Grid]
    camera_model: Any
    fixed: dict[str, Any]
    map_grid: OccupancyGrid | None
    trajectory: tuple[np.ndarray, np.ndarray] | None
    odom_log: list[tuple[float, Pose2]]
    ground_truth: Any
    T_map_odom_end: Pose2
    t_start: float
    t_end: float
    summary: dict[str, Any] = field(default_factory=dict)


class RecordingConsciousness:
    """Stands in front of a consciousness: logs every ``update`` / ``apply_correction`` and forwards it."""

    def __init__(self, inner: Any) -> None:
        self.inner = inner
        self.events: list[FuseInput | Correction] = []
        self.grids: list[_Grid] = []
        self._last_grid: tuple[OccupancyGrid, bytes] | None = None

    def __getattr__(self, name: str) -> Any:
        if name == "inner":  # not set yet (copy, unpickling)
            raise AttributeError(name)
        return getattr(self.inner, name)

    def _grid_index(self, g: OccupancyGrid | None) -> int | None:
        if g is None:
            return None
        raw = np.ascontiguousarray(g.data, dtype=np.int8).tobytes()
        last = self._last_grid
        if last is not None and last[1] == raw and last[0].origin == g.origin and last[0].stamp == g.stamp \
                and last[0].resolution == g.resolution and last[0].data.shape == g.data.shape:
            return len(self.grids) - 1
        self.grids.append(_Grid.of(g))
        self._last_grid = (g, raw)
        return len(self.grids) - 1

    def update(self, detections: Detections, scan: LaserScan, T_frame_base: Pose2, *, stamp: float,
               grid: OccupancyGrid | None = None, keyframe: tuple[int, Pose2] | None = None,
               robot_moved: bool | None = None) -> Any:
        self.events.append(FuseInput(detections, scan, T_frame_base, stamp, keyframe, robot_moved, self._grid_index(grid)))
        return self.inner.update(detections, scan, T_frame_base, stamp=stamp, grid=grid, keyframe=keyframe,
                                 robot_moved=robot_moved)

    def apply_correction(self, keyframe_pose: Any) -> int:
        poses = []
        for k in range(10**7):
            try:
                poses.append(keyframe_pose(k).as_array())
            except (IndexError, KeyError):
                break
        self.events.append(Correction(np.array(poses, dtype=np.float64).reshape(-1, 3)))
        return int(self.inner.apply_correction(keyframe_pose))


def attach_recorder(core: Any) -> RecordingConsciousness:
    """Put a :class:`RecordingConsciousness` in front of ``core``'s consciousness (a ReplayCore, before it runs)."""
    rec = RecordingConsciousness(core.state.consciousness)
    core.state.consciousness = rec
    return rec


def trace_from_core(core: Any, rec: RecordingConsciousness, key: str) -> SlamTrace:
    """The trace of a finished :class:`app.ros2.replay.ReplayCore` run whose consciousness ``rec`` recorded."""
    c = core.cfg.consciousness
    grid = core.slam.occupancy_grid(budget=10**9) if core.cfg.slam.enabled else None
    traj = core.slam.trajectory() if core.cfg.slam.enabled else None
    summary = core.summary()
    for k in ("objects", "wall_time_s", "real_time_factor", "end_reason"):
        summary.pop(k, None)
    for k in list(summary):
        if k.startswith("objects_"):
            summary.pop(k)
    return SlamTrace(key=key, events=rec.events, grids=rec.grids, camera_model=core.camera_model,
                     fixed={k: getattr(c, k) for k in TRACE_FIXED}, map_grid=grid, trajectory=traj,
                     odom_log=list(core.state.odom_log), ground_truth=core.bag.ground_truth,
                     T_map_odom_end=core.T_map_odom, t_start=core.t_start, t_end=core.state.t, summary=summary)


def save_trace(trace: SlamTrace, path: str | Path) -> Path:
    """Write ``trace`` (pickle, atomically)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + f".tmp{os.getpid()}")
    with open(tmp, "wb") as f:
        pickle.dump(trace, f, protocol=pickle.HIGHEST_PROTOCOL)
    os.replace(tmp, path)
    return path


def load_trace(path: str | Path) -> SlamTrace | None:
    """A trace written by :func:`save_trace`, or ``None`` if it is missing, corrupt or of another version."""
    try:
        with open(path, "rb") as f:
            t = pickle.load(f)
    except Exception:
        return None
    return t if isinstance(t, SlamTrace) and getattr(t, "key", None) else None


def trace_can_run(trace: SlamTrace, cfg: Any) -> str | None:
    """``None`` if ``cfg`` may be replayed from ``trace``, else why not (one line)."""
    for k, v in trace.fixed.items():
        if getattr(cfg.consciousness, k) != v:
            return f"consciousness.{k} differs from the trace's ({v!r})"
    return None


class _FrozenSlam:
    """The SLAM's results at the end of the traced replay (what the run directory reads)."""

    def __init__(self, trace: SlamTrace) -> None:
        self._t = trace
        self.skipped: dict[str, int] = {}

    @property
    def T_map_odom(self) -> Pose2:
        return self._t.T_map_odom_end

    def occupancy_grid(self, budget: int | None = None) -> OccupancyGrid:
        g = self._t.map_grid
        if g is None:
            raise RuntimeError("the traced replay ran without SLAM")
        return g

    def trajectory(self) -> tuple[np.ndarray, np.ndarray]:
        tr = self._t.trajectory
        return (np.zeros(0), np.zeros((0, 3))) if tr is None else (tr[0].copy(), tr[1].copy())


@dataclass
class _TraceState:
    consciousness: Any
    odom_log: list[tuple[float, Pose2]]
    index: int = 0


class TraceReplay:
    """A consciousness-only replay of a :class:`SlamTrace` with ``cfg``'s constants; the surface of
    :class:`app.ros2.replay.ReplayCore` that headless replay and the run directory use (``step``, ``run``,
    ``summary``, ``objects_in_map``, ``object_report``, ``slam``, ``state``, ``time``)."""

    reuse_detections = True
    fusing = True

    def __init__(self, trace: SlamTrace, cfg: Any) -> None:
        from app.ocslam.consciousness import Consciousness
        from app.ocslam.detector import score_calibration_for

        why = trace_can_run(trace, cfg)
        if why is not None:
            raise ValueError(f"SLAM trace: {why}")
        self.trace, self.cfg = trace, cfg
        self.camera_model = trace.camera_model
        # the boxes (recorded /yolo_boxes, or the replay's own detector's) are read as the configured
        # model's, as ReplayCore reads them (detector.calibration: off for boxes of another detector)
        cal = score_calibration_for(cfg.detector)
        self.state = _TraceState(Consciousness(cfg.consciousness, trace.camera_model, cal), trace.odom_log)
        self.slam = _FrozenSlam(trace)
        self.warnings = list(trace.summary.get("warnings", []))
        self.t_start, self.t_end = trace.t_start, trace.t_end
        self.wall_s = 0.0
        self.errors = 0

    @property
    def time(self) -> float:
        return self.t_end if self.state.index >= len(self.trace.events) else self.t_start

    @property
    def T_map_odom(self) -> Pose2:
        return self.trace.T_map_odom_end

    def step(self) -> FuseInput | Correction | None:
        """Feed the next traced call to the consciousness; ``None`` at the end."""
        st, ev = self.state, self.trace.events
        if st.index >= len(ev):
            return None
        e = ev[st.index]
        st.index += 1
        t0 = time.perf_counter()
        try:
            if isinstance(e, Correction):
                st.consciousness.apply_correction(e.pose)
            else:
                g = self.trace.grids[e.grid].grid() if e.grid is not None else None
                st.consciousness.update(e.detections, e.scan, e.T_frame_base, stamp=e.stamp, grid=g,
                                        keyframe=e.keyframe, robot_moved=e.robot_moved)
        except Exception:  # as the replay: one bad message never stops it
            self.errors += 1
        self.wall_s += time.perf_counter() - t0
        return e

    def run(self) -> None:
        while self.step() is not None:
            pass

    def objects_in_map(self) -> list[TrackedObject]:
        T = self.T_map_odom
        return [replace(o, pose=T @ o.pose, frame_id="map") if o.frame_id == "odom" else o
                for o in self.state.consciousness.objects]

    def object_report(self) -> Any:
        from app.ocslam.evaluation import evaluate_objects

        gt = self.trace.ground_truth
        if gt is None:
            return None
        return evaluate_objects(self.objects_in_map(), gt[0], gt[1], self.cfg.consciousness.presence_threshold)

    def summary(self) -> dict[str, Any]:
        out = dict(self.trace.summary)
        dur = float(out.get("bag_time_s", 0.0))
        out["wall_time_s"] = round(self.wall_s, 3)
        out["real_time_factor"] = round(dur / self.wall_s, 3) if self.wall_s > 0 else None
        out["slam_trace"] = self.trace.key
        out["stages_s"] = {"consciousness": round(self.wall_s, 3)}
        from app.ros2.replay import object_summary

        out.update(object_summary(self.object_report()))
        return out
