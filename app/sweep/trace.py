"""The SLAM's side of a recording, replayed once, so that a trial runs only the consciousness.

``ocslam replay BAG --reuse-detections`` (:class:`app.ros2.replay.ReplayCore`) re-runs the SLAM on every
replay, because the object map is anchored to its keyframes. Nothing the consciousness does feeds back
into the SLAM, so for trials that change only consciousness constants (and the detector's confidence
threshold, see :mod:`app.sweep.suite`) the SLAM's part is the same every time. :func:`build_trace` replays
the bag once through :class:`~app.ros2.replay.ReplayCore` with ``reuse_detections`` and records, in
order, what the consciousness was handed (:class:`app.ros2.slam_trace.RecordingConsciousness` in front of
it, so the replay's own fusion step decides the calls):

- a :class:`FuseInput` per recorded ``/yolo_boxes`` message: the boxes, the scan nearest the image moved
  to its instant, ``T_map_base`` at the image's stamp, the keyframe ``(k, T_map_kf)``, the occupancy
  grid (reduced to the three levels the consciousness reads: unknown, free (< 20), not free; zlib), and
  whether the robot moved;
- a :class:`Correction` (every keyframe's ``T_map_kf``, ``(K, 3)``) at each SLAM correction.

:func:`replay_trace` feeds them to a fresh :class:`~app.ocslam.consciousness.Consciousness` with a
trial's constants and scores the final map: the same calls, in the same order, with the same arguments
as the full replay makes, so the object map is identical (``tests/test_sweep.py`` checks it). Improved
mode only; a trial that changes ``consciousness.mode``, ``sync_tolerance_s`` or turns ``corner_check``
on when the trace was built without it needs the full replay (:func:`trace_can_run`).
"""

from __future__ import annotations

import zlib
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from app.ocslam.messages import Detections, GroundTruthObject, GroundTruthObstacle, LaserScan, OccupancyGrid
from app.ocslam.se2 import Pose2
from app.ros2.slam_trace import Correction

#: consciousness fields a trace fixes (changing them needs the full replay)
TRACE_FIXED = ("mode", "sync_tolerance_s")


@dataclass
class CompactGrid:
    """An occupancy grid reduced to ``-1`` unknown, ``0`` free (``0 ≤ v < 20``), ``100`` not free; zlib."""

    resolution: float
    origin: Pose2
    shape: tuple[int, int]
    blob: bytes
    stamp: float
    frame_id: str

    @classmethod
    def of(cls, g: OccupancyGrid) -> CompactGrid:
        v = np.asarray(g.data)
        data = np.where(v < 0, -1, np.where(v < 20, 0, 100)).astype(np.int8)
        return cls(float(g.resolution), g.origin, (int(data.shape[0]), int(data.shape[1])),
                   zlib.compress(data.tobytes(), 1), float(g.stamp), str(g.frame_id))

    def same_cells(self, other: CompactGrid) -> bool:
        """True if ``other`` decompresses to the same cells with the same geometry (its stamp may differ)."""
        return other is self or (self.blob == other.blob and self.shape == other.shape
                                 and self.resolution == other.resolution and self.origin == other.origin
                                 and self.frame_id == other.frame_id)

    def grid(self) -> OccupancyGrid:
        data = np.frombuffer(zlib.decompress(self.blob), dtype=np.int8).reshape(self.shape)
        return OccupancyGrid(self.resolution, self.origin, data, self.stamp, self.frame_id)


@dataclass
class FuseInput:
    """One ``Consciousness.update`` call's arguments (``T_map_base`` at the image's stamp)."""

    detections: Detections
    scan: LaserScan
    T_map_base: Pose2
    stamp: float
    keyframe: tuple[int, Pose2] | None
    robot_moved: bool
    grid: CompactGrid | None


@dataclass
class Trace:
    """Everything a trial needs from one recording (picklable; travels through Ray's object store)."""

    name: str
    events: list[FuseInput | Correction]
    camera_model: Any
    truth: list[GroundTruthObject]
    obstacles: list[GroundTruthObstacle]
    T_map_odom_end: Pose2
    corner_check: bool
    fixed: dict[str, Any]
    floor: float
    info: dict[str, Any] = field(default_factory=dict)


def _sweep_events(rec: Any) -> list[FuseInput | Correction]:
    """The calls :class:`app.ros2.slam_trace.RecordingConsciousness` saw, as this module's events (grids
    reduced to the three levels the consciousness reads)."""
    out: list[FuseInput | Correction] = []
    for e in rec.events:
        if isinstance(e, Correction):
            out.append(e)
        else:
            grid = CompactGrid.of(rec.grids[e.grid].grid()) if e.grid is not None else None
            out.append(FuseInput(e.detections, e.scan, e.T_frame_base, e.stamp, e.keyframe, bool(e.robot_moved), grid))
    return out


def open_bag(path: str | Path, cfg: Any):
    from app.ros2.reader import BagTopics, read_bag

    r = cfg.replay
    names = BagTopics(scan=r.scan_topic, odom=r.odom_topic, image=r.image_topic, image_raw=r.image_raw_topic,
                      camera_info=r.camera_info_topic, yolo_boxes=r.yolo_boxes_topic)
    return read_bag(path, names, with_images=False)


def build_trace(bag_path: str | Path, cfg: Any, name: str = "", floor: float = 0.0) -> Trace:
    """Replay ``bag_path`` once (SLAM re-run, recorded boxes) with ``cfg`` and record the trace."""
    import time

    from app.ros2.errors import BagError
    from app.ros2.replay import ReplayCore
    from app.ros2.slam_trace import attach_recorder

    if cfg.consciousness.mode != "improved":
        raise BagError("a trace replays the improved mode only (consciousness.mode=seed: full replay)")
    cfg = cfg.copy() if hasattr(cfg, "copy") else cfg
    cfg.set("replay.snapshot_period_s", 3600.0)  # no seeking here: no snapshots
    bag = open_bag(bag_path, cfg)
    t0 = time.perf_counter()
    core = ReplayCore(cfg, bag, reuse_detections=True)
    if not core.fusing:
        raise BagError(f"{bag_path}: no recorded boxes and camera_info: nothing to fuse")
    if bag.ground_truth is None:
        raise BagError(f"{bag_path}: no ground truth in the bag: trials cannot be scored")
    rec = attach_recorder(core)  # the replay's own fusion step, recorded as it calls the consciousness
    core.run()
    events = _sweep_events(rec)
    truth, obstacles = bag.ground_truth
    return Trace(name=name or Path(bag_path).name, events=events, camera_model=core.camera_model,
                 truth=list(truth), obstacles=list(obstacles), T_map_odom_end=core.T_map_odom,
                 corner_check=bool(cfg.consciousness.corner_check),
                 fixed={k: getattr(cfg.consciousness, k) for k in TRACE_FIXED}, floor=float(floor),
                 info={"build_s": round(time.perf_counter() - t0, 2), "frames": sum(isinstance(e, FuseInput) for e in events),
                       "corrections": sum(isinstance(e, Correction) for e in events),
                       "bag_time_s": round(core.t_end - core.t_start, 2)})


def trace_can_run(trace: Trace, cfg: Any) -> str | None:
    """None if ``cfg`` can be evaluated on ``trace``, else why not (one line)."""
    c = cfg.consciousness
    for k, v in trace.fixed.items():
        if getattr(c, k) != v:
            return f"consciousness.{k} differs from the trace's ({v!r})"
    if c.corner_check and not trace.corner_check:
        return "consciousness.corner_check on, the trace was built without the grid"
    if cfg.detector.confidence < trace.floor - 1e-12:
        return f"detector.confidence {cfg.detector.confidence} below the recording's floor {trace.floor}"
    return None


def filter_detections(dets: Detections, confidence: float) -> Detections:
    """The boxes a detector at threshold ``confidence`` would have kept (see :mod:`app.sweep.suite`)."""
    if not dets.boxes or min(b.confidence for b in dets.boxes) >= confidence:
        return dets
    return replace(dets, boxes=tuple(b for b in dets.boxes if b.confidence >= confidence))


def replay_trace(trace: Trace, cfg: Any, on_event: Callable[[Any, Any], None] | None = None) -> list:
    """The final object map (``map`` frame) of a fresh consciousness with ``cfg`` fed the trace.
    ``on_event(event, consciousness)``: called after each event (a :class:`FuseInput` or a :class:`Correction`)
    is applied, to watch the map grow (``scripts/track_life.py``)."""
    import logging

    from app.ocslam.consciousness import Consciousness
    from app.ocslam.detector import score_calibration_for

    why = trace_can_run(trace, cfg)
    if why is not None:
        raise ValueError(f"{trace.name}: {why}")
    # the recordings of a YOLO suite are keyed by the model's hash: its card's calibration is theirs
    cons = Consciousness(cfg.consciousness, trace.camera_model, score_calibration_for(cfg.detector))
    conf = float(cfg.detector.confidence)
    corner = bool(cfg.consciousness.corner_check)
    last: tuple[CompactGrid, OccupancyGrid] | None = None  # the grid changes less often than the frames
    for ev in trace.events:
        try:
            if isinstance(ev, Correction):
                cons.apply_correction(ev.pose)
            else:
                grid = None
                if corner and ev.grid is not None:
                    if last is None or not last[0].same_cells(ev.grid):
                        last = (ev.grid, ev.grid.grid())
                    elif last[0] is not ev.grid:  # the same cells: no decompression, this frame's stamp
                        last = (ev.grid, replace(last[1], stamp=ev.grid.stamp))
                    grid = last[1]
                cons.update(filter_detections(ev.detections, conf), ev.scan, ev.T_map_base, stamp=ev.stamp,
                            grid=grid, keyframe=ev.keyframe, robot_moved=ev.robot_moved)
        except Exception as ex:  # as the replay: one bad message never stops it
            logging.getLogger(__name__).warning("trace %s: frame at %.3f s skipped: %s", trace.name,
                                                getattr(ev, "stamp", float("nan")), ex)
            continue
        if on_event is not None:
            on_event(ev, cons)
    T = trace.T_map_odom_end
    return [replace(o, pose=T @ o.pose, frame_id="map") if o.frame_id == "odom" else o for o in cons.objects]


def score_trace(trace: Trace, cfg: Any) -> dict[str, Any]:
    """The paper's table (``evaluate_objects``) for ``cfg`` on ``trace``."""
    from app.ocslam.evaluation import evaluate_objects

    objs = replay_trace(trace, cfg)
    rep = evaluate_objects(objs, trace.truth, trace.obstacles, cfg.consciousness.presence_threshold).as_dict()
    return {k: rep.get(k) for k in ("in_scene", "in_map", "tp", "fn", "fp", "precision_strict", "recall", "f1",
                                     "pos_err_mean_m")}
