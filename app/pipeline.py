"""The loop: one thread owns pybullet and advances the simulator and the algorithm core.

Data flow (the paper's Figure 1)::

    wheel encoders ─► odometry ─► T_odom_base ──────────────┐
    LIDAR ─────────────────────► LaserScan ───────────────► SLAM ─► T_map_odom, grid, graph
    camera ────────────────────► Image ─► detector ─► Detections
              scan + pose at the image stamp + detections ─► consciousness ─► object map
    ground truth ─────────────────────────────────────────► evaluation (never into the above)

The web server and the headless runner both drive a :class:`Pipeline`. GUI callbacks never touch it
directly: they :meth:`Pipeline.submit` a function that the loop runs between steps.

Stages in parallel (``sim.parallel_stages``): the loop thread runs physics, odometry, LIDAR, control and
camera requests; the detector runs on its own thread (onnxruntime releases the GIL) and SLAM and the
consciousness on an estimator thread, in the order their sensor data was taken (FIFO), so each sees the
state a sequential run would. Nothing the loop thread decides depends on when a job finishes: a scan's
``map → odom`` is *published* (used for control and shown) one LIDAR period after its stamp, with or
without threads, and whoever reads the estimators (``slam``, ``consciousness``, the grid, the metrics)
from outside waits for the jobs in flight first. A seed gives the same trajectory and objects either way.

Frames: the simulator's ``world`` frame is only known to the simulator and the evaluation. ``odom`` starts
at the robot's start pose and ``map`` starts equal to ``odom`` (as slam_toolbox does), so ground truth is
compared in ``map`` through ``T_map_world = T_world_start⁻¹`` (the world file's declared start pose, the
same initial-pose knowledge AMCL or slam_toolbox is given).
"""

from __future__ import annotations

import logging
import queue
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any

import numpy as np

from app.config import Config, resolve_path
from app.loop.autonomy import Autonomy
from app.loop.fusion import CameraFusion, FusionSnapshot
from app.loop.metrics import RunMetrics
from app.loop.stages import Counters, StageJobs, StageTimer
from app.ocslam.detector import detector_score_calibration
from app.ocslam.messages import GroundTruthObject, GroundTruthObstacle, LaserScan, Twist
from app.ocslam.odometry import DiffDriveOdometry
from app.ocslam.se2 import Pose2
from app.ocslam.sync import PoseBuffer, ScanBuffer

log = logging.getLogger(__name__)

def make_detector(cfg: Config):
    """The configured detector: the YOLO model, the simulator oracle, or none."""
    kind = cfg.detector.kind
    if kind == "none":
        return None
    if kind == "oracle":
        from app.training.oracle import OracleDetector

        return OracleDetector(cfg.detector, np.random.default_rng(cfg.sim.seed + 7))
    from app.ocslam.detector import Detector

    return Detector(cfg.detector, resolve_path(cfg.detector.model_path))


def camera_render_size(cfg: Config) -> tuple[int, int]:
    """The rendered camera size: ``camera.render_width`` (keeping the aspect) or the full resolution."""
    c = cfg.camera
    if c.render_width and c.render_width < c.width:
        w = int(c.render_width)
        return w, max(1, int(round(c.height * w / c.width)))
    return int(c.width), int(c.height)


def build_camera_model(cfg: Config, robot_model: Any):
    """The camera model of the consciousness: K from the FOV at the rendered size, extrinsics from the URDF."""
    from app.ocslam.camera import CameraModel
    from app.ocslam.messages import CameraInfo

    w, h = camera_render_size(cfg)
    return CameraModel(
        info=CameraInfo.from_fov(w, h, cfg.camera.hfov_rad),
        T_base_optical=robot_model.T_base_camera_optical,
        T_base_scan=robot_model.T_base_scan,
    )


class Pipeline(Autonomy, CameraFusion, RunMetrics):
    """Simulator + odometry + SLAM + detector + consciousness, advanced one physics step at a time.

    Its parts live in ``app/loop/``: the camera frames' jobs (:class:`~app.loop.fusion.CameraFusion`),
    autonomy (:class:`~app.loop.autonomy.Autonomy`) and the metrics (:class:`~app.loop.metrics.RunMetrics`)."""

    def __init__(self, cfg: Config, *, world: Any = None, detector: Any = "auto", same_thread: bool = True) -> None:
        """``same_thread``: the loop will step (and render) on the thread that builds the pipeline, as in a
        headless run. The server builds pipelines on one thread and steps them on its loop thread: it
        passes ``False``, and the loop's own simulator then renders with TinyRenderer (an EGL context
        belongs to the thread that made it; the camera's render process keeps EGL)."""
        from app.ocslam.consciousness import Consciousness
        from app.ocslam.slam import Slam
        from app.sim.robot_model import RobotModel
        from app.sim_world import SimWorld
        from app.world.format import load_world

        self.cfg = cfg
        self.world = world if world is not None else load_world(resolve_path(cfg.sim.world))
        self.robot_model = RobotModel.load()
        self.jobs = StageJobs(bool(getattr(cfg.sim, "parallel_stages", True)))
        self._slam_results: deque[tuple[float, Future]] = deque()  # (scan stamp, T_map_odom after it)
        self._T_map_odom_pub = Pose2()
        self.detector_error: str | None = None
        if detector == "auto":
            try:
                detector = make_detector(cfg)
            except Exception as e:  # a missing model must not stop the simulation or the map
                self.detector_error = str(e)
                log.error("detector disabled: %s", e)
                detector = None
        self.detector = detector
        #: the detector's box score → probability (its card's; identity for the oracle or no detector)
        self.score_calibration = detector_score_calibration(detector)
        # the loop's own client renders only without a render process: it skips the EGL context then
        render_process = self.detector is not None and cfg.camera.async_render
        # only the primary camera rendered in the loop, on the thread that built it, uses EGL; previews
        # (no detector) are small TinyRenderer frames
        loop_renderer = None if (same_thread and self.detector is not None and not render_process) else "tiny"
        self.sim = SimWorld(self.world, cfg, seed=cfg.sim.seed, renderer=loop_renderer)
        self.T_world_start: Pose2 = self.sim.true_pose()
        self.T_map_world: Pose2 = self.T_world_start.inverse()
        self.T_base_scan: Pose2 = self.robot_model.T_base_scan_2d()
        self.odometry = DiffDriveOdometry(cfg.robot)
        self.slam = Slam(cfg.slam, T_base_scan=self.T_base_scan)
        if self.detector is not None and hasattr(self.detector, "world"):
            self.detector.world = self.world  # the oracle's visible-fraction test renders silhouettes
        self.camera_model = build_camera_model(cfg, self.robot_model)
        self.camera_worker = None
        self.renderer, self.renderer_note = self.sim.renderer, self.sim.renderer_note
        if render_process:
            from app.sim.render_worker import CameraWorker

            try:
                self.camera_worker = CameraWorker(self.world, cfg, seed=cfg.sim.seed, warmup=camera_render_size(cfg))
                self.renderer, self.renderer_note = self.camera_worker.renderer, self.camera_worker.renderer_note
            except Exception as e:  # fall back to rendering in the loop (TinyRenderer)
                log.warning("camera render process unavailable (%s); rendering in the loop", e)
                self.renderer_note = f"{self.sim.renderer_note}; in the loop (render process unavailable: {e})"
        log.info("camera renderer: %s", self.renderer_note)
        self.consciousness = Consciousness(cfg.consciousness, self.camera_model, self.score_calibration)

        self.timer = StageTimer()
        self.counters = Counters()
        self.commands: queue.Queue[Callable[[Pipeline], Any]] = queue.Queue()
        self.odom_poses = PoseBuffer(maxlen=4000)
        self.scans = ScanBuffer(maxlen=10)
        self.last_scan: LaserScan | None = None
        self.fusion = FusionSnapshot()
        self._last_fusion_pose: Pose2 | None = None
        self._slam_corrections = 0

        # sensor schedule (sim time)
        self._next_odom = 0.0
        self._next_scan = 0.0
        # the camera is not triggered with the LIDAR: half a scan period later, as unsynchronised
        # real sensors are; improved mode synchronises them, seed mode does not.
        self._next_image = 0.5 / cfg.lidar.rate_hz

        # control
        self.cmd = Twist()
        self.manual_cmd: Callable[[], Twist] | None = None  # teleop (set by the server)
        self.drive_mode = "idle"  # idle | teleop | route | goto | explore
        self.nav_status = ""
        self._goto = None
        self._route = None
        self._explorer = None
        self._nav_path_map: np.ndarray | None = None
        self.paused = False
        self._next_control = 0.0
        self._grid_cache = None
        self._grid_cache_t = -1e9

        # ground truth logs (evaluation only)
        self.truth_log: list[tuple[float, Pose2, Pose2]] = []  # (stamp, T_map_base true, T_odom_base)
        self._true_distance = 0.0
        self._last_true: Pose2 | None = None
        self.coverage_log: list[tuple[float, float]] = []
        self._true_free_area: float | None = None
        self._true_free: np.ndarray | None = None
        self.exploration_done_time: float | None = None
        self.wall_start = time.perf_counter()
        self.wall_time_s = 0.0

        self._on_reset()

    # ---------------------------------------------------------------------------------------------
    # setup helpers
    # ---------------------------------------------------------------------------------------------
    def camera_render_size(self) -> tuple[int, int]:
        return camera_render_size(self.cfg)

    # -- the estimators: read from outside only once the jobs in flight are done -------------------
    @property
    def slam(self) -> Any:
        """The SLAM node (waits for the scans in flight to be processed)."""
        self.jobs.join()
        return self._slam

    @slam.setter
    def slam(self, slam: Any) -> None:
        self.jobs.join()
        self._slam = slam
        self._slam_results.clear()
        self._T_map_odom_pub = slam.T_map_odom

    @property
    def consciousness(self) -> Any:
        """The consciousness (waits for the frames in flight to be fused)."""
        self.jobs.join()
        return self._consciousness

    @consciousness.setter
    def consciousness(self, c: Any) -> None:
        self.jobs.join()
        self._consciousness = c

    def wait_stages(self) -> None:
        """Wait until every detector, SLAM and consciousness job submitted so far is done."""
        self.jobs.join()

    def _publish_slam(self, flush: bool = False) -> None:
        """``map → odom`` of each scan becomes the loop's one LIDAR period after the scan's stamp (at the
        same step with or without threads; ``flush``: every scan processed so far, for a clock change)."""
        delay = 1.0 / self.cfg.lidar.rate_hz
        t = self.sim.time
        while self._slam_results and (flush or t + 1e-9 >= self._slam_results[0][0] + delay):
            _, fut = self._slam_results.popleft()
            try:
                self._T_map_odom_pub = fut.result()
            except Exception:  # the job logged it; keep the last pose
                pass

    def _on_reset(self) -> None:
        self.restart_odometry(Pose2())

    def restart_clock(self, t: float) -> None:
        """Continue from sim time ``t`` (a restored session): estimators reject stamps going backwards."""
        if self.camera_worker is not None:
            while self.camera_worker.pending:
                self.camera_worker.collect()
        self.jobs.join()
        self._publish_slam(flush=True)
        self.sim.set_time(t)
        now = self.sim.time
        self._next_odom = self._next_scan = now
        self._next_image = now + 0.5 / self.cfg.lidar.rate_hz
        self._next_control = now

    def restart_odometry(self, T_odom_base: Pose2) -> None:
        """Restart the wheel odometry at ``T_odom_base`` from the current encoder reading."""
        self.odometry.reset(T_odom_base)
        self.odometry.update(self.sim.read_encoders())
        self.odom_poses.clear()
        self.odom_poses.add(self.sim.time, self.odometry.T_odom_base)

    @property
    def time(self) -> float:
        return self.sim.time

    # ---------------------------------------------------------------------------------------------
    # commands from other threads
    # ---------------------------------------------------------------------------------------------
    def submit(self, fn: Callable[[Pipeline], Any]) -> None:
        """Run ``fn(pipeline)`` in the loop thread before the next step (thread-safe)."""
        self.commands.put(fn)

    def drain_commands(self) -> int:
        n = 0
        while True:
            try:
                fn = self.commands.get_nowait()
            except queue.Empty:
                return n
            try:
                fn(self)
            except Exception:  # a bad command must not kill the loop
                log.exception("command failed")
                self.counters.error("command")
            n += 1

    # ---------------------------------------------------------------------------------------------
    # frames
    # ---------------------------------------------------------------------------------------------
    @property
    def T_odom_base(self) -> Pose2:
        return self.odometry.T_odom_base

    @property
    def T_map_odom(self) -> Pose2:
        """The published ``map → odom`` (SLAM's estimate one LIDAR period after its scan, see the module)."""
        return self._T_map_odom_pub if self.cfg.slam.enabled else Pose2()

    @property
    def T_map_base(self) -> Pose2:
        return self.T_map_odom @ self.odometry.T_odom_base

    def true_pose_map(self) -> Pose2:
        """Ground truth robot pose in the map frame (evaluation / overlay only)."""
        return self.T_map_world @ self.sim.true_pose()

    def truth_objects_map(self) -> list[GroundTruthObject]:
        """Ground-truth objects re-expressed in the map frame (evaluation / overlay only)."""
        from dataclasses import replace

        T = self.T_map_world
        out = []
        for o in self.sim.ground_truth_objects():
            out.append(
                replace(o, pose=T @ o.pose, footprint=T.transform_points(o.footprint), frame_id="map")
            )
        return out

    def truth_obstacles_map(self) -> list[GroundTruthObstacle]:
        from dataclasses import replace

        T = self.T_map_world
        return [
            replace(o, footprint=T.transform_points(o.footprint), frame_id="map")
            for o in self.sim.ground_truth_obstacles()
        ]

    # ---------------------------------------------------------------------------------------------
    # the step
    # ---------------------------------------------------------------------------------------------
    def step(self) -> None:
        """Advance one physics step and run whatever sensors are due."""
        self.drain_commands()
        if self.paused:
            return
        self._publish_slam()
        self.cmd = self._control()
        with self.timer.time("physics"):
            self.sim.set_cmd_vel(self.cmd)
            self.sim.step()
        t = self.sim.time
        if t + 1e-9 >= self._next_odom:
            self._next_odom += 1.0 / self.cfg.encoders.rate_hz
            self._odometry_update()
        if t + 1e-9 >= self._next_scan:
            self._next_scan += 1.0 / self.cfg.lidar.rate_hz
            self._odometry_update()
            self._scan_update()
        if t + 1e-9 >= self._next_image:
            self._next_image += 1.0 / self.cfg.camera.rate_hz
            if self.detector is not None:
                self._odometry_update()
                self._camera_trigger()
        w = self.camera_worker
        if w is not None and w.pending and t + 1e-9 >= w.oldest_stamp() + self.cfg.camera.latency_s:
            from app.sim.render_worker import CameraWorkerError

            try:
                with self.timer.time("render"):  # only the time spent waiting for the render process
                    frame = w.collect()
            except CameraWorkerError as e:  # a lost frame, never a lost loop
                log.error("%s", e)
                self.counters.error("render")
            else:
                self._camera_process(frame)

    def _odometry_update(self) -> None:
        msg = self.odometry.update(self.sim.read_encoders())
        self.odom_poses.add(msg.stamp, msg.T_odom_base)

    def _scan_update(self) -> None:
        with self.timer.time("lidar"):
            scan = self.sim.scan()
        self.counters.scans += 1
        self.scans.add(scan)
        self.last_scan = scan
        stamp = scan.stamp
        T_odom_base = self.odom_poses.at(stamp)
        if self.cfg.slam.enabled:
            self._slam_results.append((stamp, self.jobs.estimate(self._slam_job, scan, T_odom_base)))
        # ground truth bookkeeping (evaluation only)
        true_map = self.true_pose_map()
        self.truth_log.append((stamp, true_map, T_odom_base))
        if self._last_true is not None:
            self._true_distance += true_map.distance(self._last_true)
        self._last_true = true_map

    def _slam_job(self, scan: LaserScan, T_odom_base: Pose2) -> Pose2:
        """Estimator thread: SLAM on one scan (and the consciousness' correction after a loop closure);
        returns ``T_map_odom`` after it."""
        slam = self._slam
        with self.timer.time("slam"):
            try:
                slam.process(scan, T_odom_base)
            except Exception:
                log.exception("SLAM failed on a scan; skipped")
                self.counters.error("slam")
        if slam.correction_count != self._slam_corrections:
            self._slam_corrections = slam.correction_count
            if self.cfg.consciousness.mode == "improved":
                with self.timer.time("consciousness"):
                    try:
                        self._consciousness.apply_correction(slam.keyframe_pose)
                    except Exception:
                        log.exception("consciousness correction failed")
                        self.counters.error("consciousness")
        return slam.T_map_odom

    # ---------------------------------------------------------------------------------------------
    # running
    # ---------------------------------------------------------------------------------------------
    def run_for(self, sim_seconds: float, *, stop: Callable[[], bool] | None = None) -> None:
        end = self.sim.time + sim_seconds
        while self.sim.time < end - 1e-9:
            if stop is not None and stop():
                break
            self.step()

    def reset(self) -> None:
        """Reset the world and every estimator (the map is lost: save a session first)."""
        from app.ocslam.consciousness import Consciousness
        from app.ocslam.slam import Slam

        if self.camera_worker is not None:
            while self.camera_worker.pending:  # frames of the old run
                self.camera_worker.collect()
        self.jobs.join()
        self.sim.reset()
        self.slam = Slam(self.cfg.slam, T_base_scan=self.T_base_scan)
        self.consciousness = Consciousness(self.cfg.consciousness, self.camera_model, self.score_calibration)
        self.scans.clear()
        self.last_scan = None
        self.fusion = FusionSnapshot()
        self._last_fusion_pose = None
        self._slam_corrections = 0
        self.truth_log.clear()
        self._true_distance = 0.0
        self._last_true = None
        self.stop_autonomy("reset")
        t = self.sim.time
        self._next_odom = t
        self._next_scan = t
        self._next_image = t + 0.5 / self.cfg.lidar.rate_hz
        self._on_reset()

    def close(self) -> None:
        self.jobs.close()
        if self.camera_worker is not None:
            self.camera_worker.close()
            self.camera_worker = None
        self.sim.close()
