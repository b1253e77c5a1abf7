"""Replay a bag through OCSLAM's core: odometry → SLAM, camera → detector → consciousness.

:class:`ReplayCore` consumes a :class:`app.ros2.reader.Bag`'s events in log-time order and runs the same
steps, in the same order, as :class:`app.pipeline.Pipeline` does live: each scan goes to the SLAM with
the odometry interpolated at its stamp (a loop closure re-anchors the objects); each camera frame (or,
with ``reuse_detections``, each recorded ``/yolo_boxes`` message) is fused with the scan nearest its
stamp, moved to the image's instant, and the pose at that instant. So a bag recorded by OCSLAM replays
into the live run's map, trajectory and objects.

Sensor extrinsics: ``/tf_static`` when it has the scan's and camera's frames, else ``replay.T_base_scan``
(x, y, z, roll, pitch, yaw), else the robot model's. A non-level LIDAR is levelled scan by scan
(:func:`app.ros2.extrinsics.level_scan`).

Seeking: :meth:`ReplayCore.seek` restarts from the nearest snapshot of the core's state at or before the
target (one every ``replay.snapshot_period_s`` of bag time) and runs forward from there.
"""

from __future__ import annotations

import copy
import logging
import math
import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from app.config import Config
from app.ocslam.detector import detector_score_calibration, score_calibration_for
from app.ocslam.messages import (
    Detections,
    GroundTruthObject,
    GroundTruthObstacle,
    Image,
    LaserScan,
    TrackedObject,
)
from app.ocslam.se2 import Pose2
from app.ocslam.sync import PoseBuffer, ScanBuffer, reproject_scan
from app.ros2.errors import BagError
from app.ros2.extrinsics import level_scan, matrix_from_xyzrpy, planar_mount
from app.ros2.reader import Bag, Event

log = logging.getLogger(__name__)


@dataclass
class ReplayCounters:
    scans: int = 0
    odom: int = 0
    images: int = 0
    detections: int = 0
    fused_frames: int = 0
    skipped_frames: dict[str, int] = field(default_factory=dict)
    errors: dict[str, int] = field(default_factory=dict)

    def skip(self, reason: str) -> None:
        self.skipped_frames[reason] = self.skipped_frames.get(reason, 0) + 1

    def error(self, reason: str) -> None:
        self.errors[reason] = self.errors.get(reason, 0) + 1


@dataclass
class _State:
    """Everything that evolves while replaying (deep-copied for snapshots)."""

    index: int = 0
    t: float = 0.0
    slam: Any = None
    consciousness: Any = None
    odom_poses: PoseBuffer = field(default_factory=lambda: PoseBuffer(maxlen=4000))
    scans: ScanBuffer = field(default_factory=lambda: ScanBuffer(maxlen=10))
    last_scan: LaserScan | None = None
    last_image: Image | None = None
    last_detections: Detections | None = None
    last_fusion_pose: Pose2 | None = None
    corrections: int = 0
    counters: ReplayCounters = field(default_factory=ReplayCounters)
    truth: list[tuple[float, Pose2]] = field(default_factory=list)
    odom_log: list[tuple[float, Pose2]] = field(default_factory=list)


def _mount_4x4(T: Pose2, z: float) -> np.ndarray:
    M = np.eye(4)
    c, s = math.cos(T.yaw), math.sin(T.yaw)
    M[:2, :2] = [[c, -s], [s, c]]
    M[:3, 3] = [T.x, T.y, z]
    return M



def object_summary(report: Any) -> dict[str, Any]:
    """A run summary's object keys from an ``evaluate_objects`` report (empty without one): the whole
    report under ``objects`` and its headline figures as ``objects_<key>``."""
    if report is None:
        return {}
    d = report.as_dict()
    out: dict[str, Any] = {"objects": d}
    for key in ("in_scene", "in_map", "tp", "fn", "precision_strict", "precision_lenient", "recall",
                "pos_err_mean_m", "pos_err_max_m"):
        if key in d:
            out[f"objects_{key}"] = d[key]
    return out

class ReplayCore:
    """OCSLAM's core driven by a bag. ``detector``: ``"auto"`` (the configured one, when the bag has a
    camera and ``reuse_detections`` is off), ``None``, or a detector object with ``detect(Image)``."""

    def __init__(self, cfg: Config, bag: Bag, *, reuse_detections: bool = False, detector: Any = "auto") -> None:
        from app.ocslam.camera import CameraModel
        from app.ocslam.consciousness import Consciousness
        from app.ocslam.slam import Slam
        from app.sim.robot_model import RobotModel

        self.cfg = cfg
        self.bag = bag
        self.reuse_detections = reuse_detections
        self.warnings: list[str] = list(bag.warnings)
        robot = RobotModel.load()
        # LIDAR extrinsic: /tf_static, else config, else the robot model
        scan_frame = self._first_scan_frame()
        T_scan = bag.T_base(scan_frame) if scan_frame else None
        if T_scan is not None:
            self.extrinsic_source = "/tf_static"
        elif cfg.replay.T_base_scan:
            if len(cfg.replay.T_base_scan) != 6:
                raise BagError(f"replay.T_base_scan must be [x, y, z, roll, pitch, yaw], got {cfg.replay.T_base_scan}")
            T_scan = matrix_from_xyzrpy(cfg.replay.T_base_scan)
            self.extrinsic_source = "config replay.T_base_scan"
        else:
            T_scan = np.asarray(robot.T_base_scan, dtype=np.float64)
            self.extrinsic_source = "robot model"
            if not bag.ocslam_recording:
                self.warnings.append(f"no /tf_static for {scan_frame!r}: LIDAR extrinsic from the robot model "
                                     "(set replay.T_base_scan=[x,y,z,roll,pitch,yaw])")
        self.T_base_scan_3d = T_scan
        self.T_base_scan: Pose2 = planar_mount(T_scan)  # the level frame the core sees
        self.scan_is_level = abs(T_scan[2, 2] - 1.0) < 1e-6
        # camera: calibration from the bag, mount from /tf_static or the robot model
        self.has_camera = bag.camera_info is not None and (bag.has_camera or (reuse_detections and bag.has_boxes))
        self.camera_model = None
        if bag.camera_info is not None:
            T_opt = bag.T_base(bag.camera_info.frame_id.lstrip("/"))
            if T_opt is None:
                T_opt = np.asarray(robot.T_base_camera_optical, dtype=np.float64)
            T_level = _mount_4x4(self.T_base_scan, float(T_scan[2, 3])) if not self.scan_is_level else T_scan
            self.camera_model = CameraModel(info=bag.camera_info, T_base_optical=T_opt, T_base_scan=T_level)
        else:
            from app.pipeline import build_camera_model

            self.camera_model = build_camera_model(cfg, robot)
        self.detector = None
        self.detector_error: str | None = None
        if self.has_camera and not reuse_detections:
            if detector == "auto":
                if cfg.detector.kind == "oracle":
                    self.warnings.append("detector.kind=oracle needs the simulator: replay uses the YOLO model")
                if cfg.detector.kind != "none":
                    try:
                        from app.config import resolve_path
                        from app.ocslam.detector import Detector

                        detector = Detector(cfg.detector, resolve_path(cfg.detector.model_path))
                    except Exception as e:
                        self.detector_error = str(e)
                        self.warnings.append(f"detector disabled: {e}")
                        detector = None
                else:
                    detector = None
            self.detector = detector
        if reuse_detections and not bag.has_boxes:
            self.warnings.append(f"--reuse-detections: the bag has no {cfg.replay.yolo_boxes_topic} messages: mapping only")
        self.fusing = self.has_camera and (self.detector is not None or (reuse_detections and bag.has_boxes))
        self._Slam, self._Consciousness = Slam, Consciousness
        self.state = self._fresh_state()
        self.snapshots: list[_State] = []
        #: snapshots of the state for seeking (the web timeline); a headless replay never seeks
        self.keep_snapshots = True
        self.timer: dict[str, float] = {"slam": 0.0, "detector": 0.0, "consciousness": 0.0, "decode": 0.0}
        self.wall_s = 0.0
        self.t_start = bag.events[0].t if bag.events else 0.0
        self.t_end = bag.events[-1].t if bag.events else 0.0

    def _first_scan_frame(self) -> str | None:
        for e in self.bag.events:
            if e.kind == "scan":
                return e.decode().frame_id.lstrip("/")
        return None

    def _fresh_state(self) -> _State:
        s = _State()
        s.slam = self._Slam(self.cfg.slam, T_base_scan=self.T_base_scan)
        # the detector run here calibrates its own scores; recorded /yolo_boxes are read as the configured
        # model's (an app recording's; detector.calibration: off for boxes of another detector)
        cal = (detector_score_calibration(self.detector) if self.detector is not None and not self.reuse_detections
               else score_calibration_for(self.cfg.detector))
        s.consciousness = self._Consciousness(self.cfg.consciousness, self.camera_model, cal)
        return s

    # -- frames ------------------------------------------------------------------------------------
    @property
    def time(self) -> float:
        return self.state.t

    @property
    def slam(self):
        return self.state.slam

    @property
    def consciousness(self):
        return self.state.consciousness

    @property
    def T_map_odom(self) -> Pose2:
        return self.state.slam.T_map_odom if self.cfg.slam.enabled else Pose2()

    @property
    def T_odom_base(self) -> Pose2:
        latest = self.state.odom_poses.latest()
        return latest[1] if latest is not None else Pose2()

    @property
    def T_map_base(self) -> Pose2:
        return self.T_map_odom @ self.T_odom_base

    @property
    def done(self) -> bool:
        return self.state.index >= len(self.bag.events)

    # -- stepping ----------------------------------------------------------------------------------
    def step(self) -> Event | None:
        """Process the next event; None at the end of the bag."""
        st = self.state
        if st.index >= len(self.bag.events):
            return None
        if self.keep_snapshots and (not self.snapshots or st.t >= self.snapshots[-1].t + self.cfg.replay.snapshot_period_s):
            self.snapshots.append(copy.deepcopy(st))
        e = self.bag.events[st.index]
        st.index += 1
        st.t = e.t
        t0 = time.perf_counter()
        try:
            self._process(e)
        except Exception as ex:  # one bad message never stops the replay
            log.warning("replay: %s message at %.3f s skipped: %s", e.kind, e.t, ex)
            st.counters.error(e.kind)
        self.wall_s += time.perf_counter() - t0
        return e

    def run_until(self, t: float) -> int:
        """Process every event logged at or before ``t``. Returns how many."""
        n = 0
        ev = self.bag.events
        while self.state.index < len(ev) and ev[self.state.index].t <= t + 1e-12:
            self.step()
            n += 1
        return n

    def run(self) -> None:
        while self.step() is not None:
            pass

    def step_scan(self) -> bool:
        """Run up to and including the next scan (the timeline's "step"). False at the end."""
        while True:
            e = self.step()
            if e is None:
                return False
            if e.kind == "scan":
                return True

    def seek(self, t: float) -> None:
        """Go to bag time ``t``: from the current state if no later snapshot lies before ``t``, else from
        the latest snapshot at or before ``t`` (or the start), running forward to ``t``."""
        snap = None
        for s in self.snapshots:
            if s.t <= t + 1e-12:
                snap = s
        st = self.state
        if not (st.t <= t + 1e-12 and (snap is None or snap.t <= st.t)):
            self.state = copy.deepcopy(snap) if snap is not None else self._fresh_state()
        self.run_until(t)

    # -- messages ----------------------------------------------------------------------------------
    def _process(self, e: Event) -> None:
        st = self.state
        k = e.kind
        if k in ("odom", "tf"):
            d = e.decode()
            if d is None:
                return
            stamp, T = d
            st.odom_poses.add(stamp, T)
            st.odom_log.append((stamp, T))
            st.counters.odom += 1
        elif k == "scan":
            t0 = time.perf_counter()
            scan = e.decode()
            if not self.scan_is_level:
                scan, _ = level_scan(scan, self.T_base_scan_3d)
            self.timer["decode"] += time.perf_counter() - t0
            self._scan_update(scan)
        elif k in ("image", "image_raw"):
            if self.detector is None or self.reuse_detections or not self.fusing:
                return
            t0 = time.perf_counter()
            img = e.decode()
            self.timer["decode"] += time.perf_counter() - t0
            self._camera_process(img)
        elif k == "boxes":
            if not self.reuse_detections or not self.fusing:
                return
            dets = e.decode()
            st.counters.images += 1
            st.counters.detections += len(dets)
            st.last_detections = dets
            self._fuse(dets)
        elif k == "map":
            if self.cfg.slam.enabled:  # the live recorder built /map here: keep the lazy grid in step
                t0 = time.perf_counter()
                st.slam.occupancy_grid()
                self.timer["slam"] += time.perf_counter() - t0
        elif k == "gt_pose":
            st.truth.append(e.decode())

    def _scan_update(self, scan: LaserScan) -> None:
        st = self.state
        st.counters.scans += 1
        st.scans.add(scan)
        st.last_scan = scan
        if not len(st.odom_poses):
            st.counters.skip("scan_before_odometry")
            return
        T_odom_base = st.odom_poses.at(scan.stamp)
        if self.cfg.slam.enabled:
            t0 = time.perf_counter()
            try:
                st.slam.process(scan, T_odom_base)
            except Exception:
                log.exception("SLAM failed on a scan; skipped")
                st.counters.error("slam")
            self.timer["slam"] += time.perf_counter() - t0
            if st.slam.correction_count != st.corrections:
                st.corrections = st.slam.correction_count
                if self.cfg.consciousness.mode == "improved" and self.fusing:
                    t0 = time.perf_counter()
                    st.consciousness.apply_correction(st.slam.keyframe_pose)
                    self.timer["consciousness"] += time.perf_counter() - t0

    def _camera_process(self, img: Image) -> None:
        st = self.state
        st.counters.images += 1
        t0 = time.perf_counter()
        try:
            dets = self.detector.detect(img)
        except Exception:
            log.exception("detector failed on a frame; skipped")
            st.counters.error("detector")
            return
        finally:
            self.timer["detector"] += time.perf_counter() - t0
        st.counters.detections += len(dets)
        st.last_image = img
        st.last_detections = dets
        self._fuse(dets)

    def _fuse(self, dets: Detections) -> None:
        """The pipeline's fusion step (``Pipeline._fuse``) on replayed data."""
        st = self.state
        c = self.cfg.consciousness
        stamp = dets.stamp
        if not len(st.odom_poses):
            st.counters.skip("no_odometry")
            return
        t0 = time.perf_counter()
        try:
            if c.mode == "seed":
                scan = st.scans.latest()
                if scan is None:
                    st.counters.skip("no_scan")
                    return
                T = st.odom_poses.latest()[1]
                moved = st.last_fusion_pose is None or T != st.last_fusion_pose
                st.last_fusion_pose = T
                st.consciousness.update(dets, scan, T, stamp=stamp, robot_moved=moved)
            else:
                scan = st.scans.nearest(stamp, c.sync_tolerance_s)
                if scan is None:
                    st.counters.skip("no_synced_scan")
                    return
                T_odom_img = st.odom_poses.at(stamp)
                T_odom_scan = st.odom_poses.at(scan.stamp)
                if scan.stamp != stamp:
                    scan = reproject_scan(scan, self.T_base_scan, T_odom_img.between(T_odom_scan), stamp)
                T = self.T_map_odom @ T_odom_img
                kf = None
                if self.cfg.slam.enabled:
                    k = st.slam.keyframe_at(stamp)
                    if k is not None:
                        kf = (k, st.slam.keyframe_pose(k))
                grid = st.slam.occupancy_grid() if (self.cfg.slam.enabled and c.corner_check) else None
                last = st.last_fusion_pose
                moved = last is None or T.distance(last) > 1e-4 or abs(T.yaw - last.yaw) > 1e-4
                st.last_fusion_pose = T
                st.consciousness.update(dets, scan, T, stamp=stamp, grid=grid, keyframe=kf, robot_moved=moved)
            st.counters.fused_frames += 1
        finally:
            self.timer["consciousness"] += time.perf_counter() - t0

    # -- results -----------------------------------------------------------------------------------
    def objects_in_map(self) -> list[TrackedObject]:
        """The object map in ``map`` (seed mode's ``odom`` objects through the current map → odom)."""
        T = self.T_map_odom
        return [replace(o, pose=T @ o.pose, frame_id="map") if o.frame_id == "odom" else o
                for o in self.state.consciousness.objects]

    def ground_truth(self) -> tuple[list[GroundTruthObject], list[GroundTruthObstacle]] | None:
        return self.bag.ground_truth

    def object_report(self):
        from app.ocslam.evaluation import evaluate_objects

        gt = self.bag.ground_truth
        if gt is None:
            return None
        return evaluate_objects(self.objects_in_map(), gt[0], gt[1], self.cfg.consciousness.presence_threshold)

    def summary(self) -> dict[str, Any]:
        st = self.state
        dur = max(st.t - self.t_start, 0.0)
        out: dict[str, Any] = {
            "bag": str(self.bag.path),
            "bag_time_s": round(dur, 3),
            "wall_time_s": round(self.wall_s, 3),
            "real_time_factor": round(dur / self.wall_s, 3) if self.wall_s > 0 else None,
            "reuse_detections": self.reuse_detections,
            "detector": "recorded /yolo_boxes" if self.reuse_detections else (
                self.cfg.detector.kind if self.detector is not None else "none"),
            "consciousness_mode": self.cfg.consciousness.mode,
            "lidar_extrinsic": self.extrinsic_source,
            "T_base_scan_level": [round(v, 6) for v in self.T_base_scan],
            "warnings": list(self.warnings),
        }
        if self.cfg.slam.enabled and st.truth:
            from app.ocslam.slam import metrics

            stamps, est = st.slam.trajectory()
            ts = np.array([s for s, _ in st.truth])
            true = np.array([p.as_array() for _, p in st.truth])
            if len(stamps):
                idx = np.clip(np.searchsorted(ts, stamps), 0, len(ts) - 1)
                ok = np.abs(ts[idx] - stamps) < 1e-6
                if ok.any():
                    out["slam_ate_rmse_m"] = float(metrics.ate_rmse(est[ok], true[idx[ok]]))
        if self.fusing:
            out.update(object_summary(self.object_report()))
        out["stages_s"] = {k: round(v, 3) for k, v in self.timer.items()}
        c = st.counters
        out["counters"] = {"scans": c.scans, "odometry": c.odom, "images": c.images, "detections": c.detections,
                           "fused_frames": c.fused_frames, "skipped": dict(c.skipped_frames), "errors": dict(c.errors),
                           "slam_skipped": dict(getattr(st.slam, "skipped", {}))}
        return out
