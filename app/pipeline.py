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
import math
import queue
import threading
import time
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from app.config import Config, resolve_path
from app.ocslam.messages import (
    Detections,
    GroundTruthObject,
    GroundTruthObstacle,
    Image,
    LaserScan,
    Twist,
)
from app.ocslam.odometry import DiffDriveOdometry
from app.ocslam.se2 import Pose2
from app.ocslam.sync import PoseBuffer, ScanBuffer, reproject_scan

log = logging.getLogger(__name__)

#: autonomy (route, go-to, exploration) control rate in sim time
CONTROL_HZ = 20.0

STAGES = ("physics", "lidar", "render", "detector", "slam", "consciousness", "ui")


class StageTimer:
    """Per-stage wall-clock accounting: totals (for benchmarks) and a smoothed recent value (for the UI)."""

    def __init__(self, stages: tuple[str, ...] = STAGES) -> None:
        self.total_s = {s: 0.0 for s in stages}
        self.calls = {s: 0 for s in stages}
        self.recent_ms = {s: 0.0 for s in stages}
        self._lock = threading.Lock()  # stages are timed on the loop, detector and estimator threads

    def add(self, stage: str, seconds: float) -> None:
        with self._lock:
            self.total_s[stage] = self.total_s.get(stage, 0.0) + seconds
            self.calls[stage] = self.calls.get(stage, 0) + 1
            prev = self.recent_ms.get(stage, 0.0)
            self.recent_ms[stage] = 0.9 * prev + 0.1 * seconds * 1e3 if prev else seconds * 1e3

    def time(self, stage: str):
        timer = self

        class _Ctx:
            def __enter__(self_inner):
                self_inner.t0 = time.perf_counter()

            def __exit__(self_inner, *exc):
                timer.add(stage, time.perf_counter() - self_inner.t0)
                return False

        return _Ctx()

    def per_call_ms(self) -> dict[str, float]:
        return {s: (1e3 * self.total_s[s] / self.calls[s]) if self.calls.get(s) else 0.0 for s in self.total_s}

    def per_sim_second_ms(self, sim_seconds: float) -> dict[str, float]:
        if sim_seconds <= 0:
            return {s: 0.0 for s in self.total_s}
        return {s: 1e3 * v / sim_seconds for s, v in self.total_s.items()}


@dataclass
class FusionSnapshot:
    """What the last camera frame produced, for the UI and tests."""

    stamp: float = -1.0
    image: Image | None = None
    detections: Detections | None = None
    report: Any = None  # consciousness.FrameReport
    T_frame_base: Pose2 | None = None  # robot pose used for the fusion, in the objects' frame
    synced_scan_dt: float = 0.0  # |image stamp − scan stamp| used


@dataclass
class Counters:
    scans: int = 0
    images: int = 0
    detections: int = 0
    fused_frames: int = 0
    skipped_frames: dict[str, int] = field(default_factory=dict)
    errors: dict[str, int] = field(default_factory=dict)
    _lock: Any = field(default_factory=threading.Lock, repr=False, compare=False)

    def skip(self, reason: str) -> None:
        with self._lock:
            self.skipped_frames[reason] = self.skipped_frames.get(reason, 0) + 1

    def error(self, reason: str) -> None:
        with self._lock:
            self.errors[reason] = self.errors.get(reason, 0) + 1


class StageJobs:
    """Where the detector and estimator jobs run: on two worker threads (``parallel``) or inline.

    ``detect(fn, ...)`` runs on the detector thread; ``estimate(fn, ...)`` on the estimator thread, in
    submission order. Both return a :class:`Future`; inline, it is already done. Jobs catch their own
    errors (a failed job never stops the loop). :meth:`join` waits for every estimator job submitted.
    """

    def __init__(self, parallel: bool) -> None:
        self.parallel = bool(parallel)
        self._det = ThreadPoolExecutor(1, thread_name_prefix="ocslam-detector") if self.parallel else None
        self._est = ThreadPoolExecutor(1, thread_name_prefix="ocslam-estimators") if self.parallel else None
        self._pending: deque[Future] = deque()
        #: guards ``_pending``: the loop thread and the GUI's threads all wait for the jobs in flight
        self._lock = threading.Lock()
        self._threads: set[int] = set()

    @staticmethod
    def _inline(fn: Callable[..., Any], *args: Any) -> Future:
        f: Future = Future()
        try:
            f.set_result(fn(*args))
        except BaseException as e:  # noqa: BLE001 - handed to whoever reads the future
            f.set_exception(e)
        return f

    def _wrap(self, fn: Callable[..., Any]) -> Callable[..., Any]:
        def run(*args: Any) -> Any:
            self._threads.add(threading.get_ident())
            return fn(*args)

        return run

    def detect(self, fn: Callable[..., Any], *args: Any) -> Future:
        if self._det is None:
            return self._inline(fn, *args)
        return self._det.submit(self._wrap(fn), *args)

    def estimate(self, fn: Callable[..., Any], *args: Any) -> Future:
        if self._est is None:
            return self._inline(fn, *args)
        with self._lock:  # submitted and queued together, so the queue keeps the jobs' order
            f = self._est.submit(self._wrap(fn), *args)
            self._pending.append(f)
        return f

    def in_worker(self) -> bool:
        return threading.get_ident() in self._threads

    def join(self) -> None:
        """Wait for every estimator job submitted so far (a no-op on a worker thread or inline)."""
        if self._est is None or self.in_worker():
            return
        while True:
            with self._lock:
                if not self._pending:
                    return
                f = self._pending[0]
            try:
                f.result()
            except Exception:  # jobs log their own errors
                pass
            with self._lock:  # another waiter may have dropped it already
                if self._pending and self._pending[0] is f:
                    self._pending.popleft()

    def busy(self) -> int:
        """Estimator jobs not finished yet."""
        with self._lock:
            while self._pending and self._pending[0].done():
                self._pending.popleft()
            return sum(not f.done() for f in self._pending)

    def close(self) -> None:
        self.join()
        for ex in (self._det, self._est):
            if ex is not None:
                ex.shutdown(wait=True)
        self._det = self._est = None


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
    from app.ocslam.messages import CameraInfo
    from app.ocslam.camera import CameraModel

    w, h = camera_render_size(cfg)
    return CameraModel(
        info=CameraInfo.from_fov(w, h, cfg.camera.hfov_rad),
        T_base_optical=robot_model.T_base_camera_optical,
        T_base_scan=robot_model.T_base_scan,
    )


class Pipeline:
    """Simulator + odometry + SLAM + detector + consciousness, advanced one physics step at a time."""

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
        self.consciousness = Consciousness(cfg.consciousness, self.camera_model)

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
    def submit(self, fn: Callable[["Pipeline"], Any]) -> None:
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
    # driving
    # ---------------------------------------------------------------------------------------------
    def _navigation(self):
        from app.ocslam import navigation

        return navigation

    def stop_autonomy(self, status: str = "") -> None:
        if self._explorer is not None:
            self._explorer.stop()
        if self._goto is not None:
            self._goto.cancel()
            self._goto = None
        self.drive_mode = "idle"
        self._route = None
        self._explorer = None
        self._nav_path_map = None
        self.nav_status = status

    def follow_route(self, name: str) -> None:
        """Follow a named route of the world file (waypoints converted to the map frame)."""
        nav = self._navigation()
        if name not in self.world.routes:
            raise KeyError(f"world has no route {name!r} (routes: {', '.join(self.world.routes) or 'none'})")
        pts_world = np.asarray(self.world.routes[name], dtype=float).reshape(-1, 2)
        pts_map = self.T_map_world.transform_points(pts_world)
        self._route = nav.RouteFollower(self.cfg.robot, pts_map)
        self._nav_path_map = pts_map
        self.drive_mode = "route"
        self.nav_status = f"route {name}: {len(pts_map)} waypoints"

    def go_to(self, goal_map_xy: tuple[float, float]) -> bool:
        """Click-to-go: drive to ``goal_map_xy`` along an A* path on the SLAM grid (inflated by the robot's
        radius), replanning as the map grows. False if no path exists now."""
        nav = self._navigation()
        self.stop_autonomy()
        ctl = nav.GoToController(self.cfg.robot, goal_map_xy)
        ctl.compute(self.grid(), self.T_map_base, self.last_scan, self.T_base_scan, now=self.time)
        if ctl.status == "failed":
            self.nav_status = f"no path to ({goal_map_xy[0]:.2f}, {goal_map_xy[1]:.2f})"
            return False
        self._goto = ctl
        self._nav_path_map = ctl.path
        self.drive_mode = "goto"
        self.nav_status = f"going to ({goal_map_xy[0]:.2f}, {goal_map_xy[1]:.2f})"
        return True

    def explore(self) -> None:
        """Frontier exploration until no reachable frontier is left (or the user takes over)."""
        nav = self._navigation()
        self._explorer = nav.ExplorationController(self.cfg.robot)
        self._explorer.start()
        self._nav_path_map = None
        self.exploration_done_time = None
        self.drive_mode = "explore"
        self.nav_status = "exploring"

    def grid(self):
        """The SLAM occupancy grid, rebuilt at most at ``slam.map_hz`` (sim time) for planning."""
        if self._grid_cache is None or self.time - self._grid_cache_t >= 1.0 / self.cfg.slam.map_hz:
            self._grid_cache = self.slam.occupancy_grid()
            self._grid_cache_t = self.time
        return self._grid_cache

    def _control(self) -> Twist:
        manual = self.manual_cmd() if self.manual_cmd is not None else Twist()
        if manual.linear_x or manual.angular_z:
            if self.drive_mode not in ("idle", "teleop"):
                self.stop_autonomy("teleop took over")
            self.drive_mode = "teleop"
            return manual
        if self.drive_mode == "teleop":
            self.drive_mode = "idle"
        if self.drive_mode in ("idle", "teleop"):
            return Twist()
        if self.time < self._next_control - 1e-9:
            return self.cmd  # autonomy runs at CONTROL_HZ; hold the command in between
        self._next_control = self.time + 1.0 / CONTROL_HZ
        scan = self.last_scan
        T = self.T_map_base
        if self.drive_mode == "route" and self._route is not None:
            twist = self._route.compute(T, scan, self.T_base_scan)
            if self._route.done:
                self.stop_autonomy("route done")
                return Twist()
            return twist
        if self.drive_mode == "goto" and self._goto is not None:
            twist = self._goto.compute(self.grid(), T, scan, self.T_base_scan, now=self.time)
            self._nav_path_map = self._goto.path
            if self._goto.status in ("arrived", "failed"):
                self.stop_autonomy("arrived" if self._goto.status == "arrived" else "go-to failed: no path")
                return Twist()
            return twist
        if self.drive_mode == "explore" and self._explorer is not None:
            twist = self._explorer.compute(self.grid(), T, scan, self.T_base_scan, now=self.time)
            self._nav_path_map = self._explorer.path
            if self._explorer.status == "done":
                self.exploration_done_time = self.time
                self.stop_autonomy("exploration done: no reachable frontier left")
                return Twist()
            return twist
        return Twist()

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

    def _camera_trigger(self) -> None:
        """A camera frame is due: render it now, or ask the render process for it."""
        w, h = self.camera_render_size()
        oracle = self.cfg.detector.kind == "oracle"
        if self.camera_worker is not None:
            self.camera_worker.request(self.sim.time, self.sim.true_pose(), width=w, height=h, segmentation=oracle)
            return
        with self.timer.time("render"):
            frame = self.sim.render_camera(w, h, segmentation=oracle)
        self._camera_process(frame)

    def _camera_process(self, frame) -> None:
        """Detector and fusion on one camera frame (stamped when it was taken). The loop thread takes
        what the fusion needs from its buffers now (the scan, the odometry poses); the detector and the
        fusion run as jobs (see :class:`StageJobs`)."""
        self.counters.images += 1
        truth = self.sim.ground_truth_objects() if self.cfg.detector.kind == "oracle" else None
        dets = self.jobs.detect(self._detect_job, frame, truth)
        self.jobs.estimate(self._fuse_job, frame, dets, self._fusion_inputs(frame.stamp))

    def _detect_job(self, frame, truth) -> Detections | None:
        with self.timer.time("detector"):
            try:
                if truth is not None:
                    return self.detector.detect(frame, truth)
                return self.detector.detect(frame.image)
            except Exception:
                log.exception("detector failed on a frame; skipped")
                self.counters.error("detector")
                return None

    def _fusion_inputs(self, stamp: float) -> tuple:
        """Loop thread: the sensor data a frame at ``stamp`` is fused with (taken when it is processed)."""
        c = self.cfg.consciousness
        if c.mode == "seed":  # the original: the latest scan and the latest raw odometry pose
            return ("seed", self.scans.latest(), self.odometry.T_odom_base)
        scan = self.scans.nearest(stamp, c.sync_tolerance_s)
        if scan is None:
            return ("improved", None, None, None)
        return ("improved", scan, self.odom_poses.at(stamp), self.odom_poses.at(scan.stamp))

    def _fuse_job(self, frame, dets_future: Future, inputs: tuple) -> None:
        """Estimator thread: wait for the frame's detections, then fuse them."""
        dets = dets_future.result()
        if dets is None:
            return
        self.counters.detections += len(dets)
        snap = FusionSnapshot(
            stamp=self.fusion.stamp, image=frame.image, detections=dets, report=self.fusion.report,
            T_frame_base=self.fusion.T_frame_base, synced_scan_dt=self.fusion.synced_scan_dt,
        )
        with self.timer.time("consciousness"):
            try:
                self._fuse(dets, inputs, snap)
            except Exception:
                log.exception("consciousness failed on a frame; skipped")
                self.counters.error("consciousness")
        self.fusion = snap

    def _fuse(self, dets: Detections, inputs: tuple, snap: FusionSnapshot) -> None:
        c = self.cfg.consciousness
        stamp = dets.stamp
        cons = self._consciousness
        if inputs[0] == "seed":
            # the original: the latest scan and the latest raw odometry pose, in the odom frame;
            # frames count only when the pose changed since the previous message
            _, scan, T = inputs
            if scan is None:
                self.counters.skip("no_scan")
                return
            moved = self._last_fusion_pose is None or T != self._last_fusion_pose
            self._last_fusion_pose = T
            report = cons.update(dets, scan, T, stamp=stamp, robot_moved=moved)
            snap.synced_scan_dt = abs(stamp - scan.stamp)
        else:
            _, scan, T_odom_img, T_odom_scan = inputs
            if scan is None:
                self.counters.skip("no_synced_scan")
                return
            if scan.stamp != stamp:
                scan = reproject_scan(scan, self.T_base_scan, T_odom_img.between(T_odom_scan), stamp)
            slam = self._slam
            T = (slam.T_map_odom if self.cfg.slam.enabled else Pose2()) @ T_odom_img
            kf = None
            if self.cfg.slam.enabled:
                k = slam.keyframe_at(stamp)
                if k is not None:
                    kf = (k, slam.keyframe_pose(k))
            grid = slam.occupancy_grid() if (self.cfg.slam.enabled and c.corner_check) else None
            moved = self._last_fusion_pose is None or T.distance(self._last_fusion_pose) > 1e-4 or abs(
                T.yaw - self._last_fusion_pose.yaw
            ) > 1e-4
            self._last_fusion_pose = T
            report = cons.update(dets, scan, T, stamp=stamp, grid=grid, keyframe=kf, robot_moved=moved)
            snap.synced_scan_dt = 0.0
        self.counters.fused_frames += 1
        snap.stamp = stamp
        snap.report = report
        snap.T_frame_base = T

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
        self.consciousness = Consciousness(self.cfg.consciousness, self.camera_model)
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

    # ---------------------------------------------------------------------------------------------
    # metrics
    # ---------------------------------------------------------------------------------------------
    def odometry_errors(self) -> dict[str, float]:
        """Raw odometry against ground truth (odom frame = map frame at start)."""
        if not self.truth_log:
            return {"odom_final_error_m": 0.0, "odom_rms_error_m": 0.0, "odom_final_heading_error_deg": 0.0}
        true = np.array([p.as_array() for _, p, _ in self.truth_log])
        odom = np.array([o.as_array() for _, _, o in self.truth_log])
        err = np.hypot(*(true[:, :2] - odom[:, :2]).T)
        dyaw = math.degrees(abs(math.remainder(true[-1, 2] - odom[-1, 2], 2 * math.pi)))
        return {
            "odom_final_error_m": float(err[-1]),
            "odom_rms_error_m": float(np.sqrt(np.mean(err**2))),
            "odom_final_heading_error_deg": float(dyaw),
        }

    def slam_metrics(self) -> dict[str, float]:
        from app.ocslam.slam import metrics

        out: dict[str, float] = {}
        if not (self.cfg.slam.enabled and self.truth_log):
            return out
        stamps, est = self.slam.trajectory()
        if len(stamps):
            truth_stamps = np.array([s for s, _, _ in self.truth_log])
            true = np.array([p.as_array() for _, p, _ in self.truth_log])
            idx = np.clip(np.searchsorted(truth_stamps, stamps), 0, len(truth_stamps) - 1)
            ok = np.abs(truth_stamps[idx] - stamps) < 1e-6
            if ok.any():
                out["slam_ate_rmse_m"] = float(metrics.ate_rmse(est[ok], true[idx[ok]]))
        grid = self.slam.occupancy_grid()
        polys = [o.footprint for o in self.truth_obstacles_map()]
        lidar_z = self.robot_model.lidar_height_m
        polys += [o.footprint for o in self.truth_objects_map() if o.z_min <= lidar_z <= o.z_max and not o.legged]
        p, r = metrics.map_agreement(grid, polys)
        out["map_precision"] = float(p)
        out["map_recall"] = float(r)
        return out

    # -- exploration coverage (evaluation only: uses the world's true geometry) ------------------
    def _true_free_cells(self, res: float = 0.05) -> np.ndarray:
        """``(N, 2)`` centres, in the map frame, of the true free cells reachable from the start."""
        if getattr(self, "_true_free", None) is not None:
            return self._true_free
        import shapely
        from scipy import ndimage

        xmin, ymin, xmax, ymax = self.world.bounds()
        xs = np.arange(xmin + res / 2, xmax, res)
        ys = np.arange(ymin + res / 2, ymax, res)
        gx, gy = np.meshgrid(xs, ys)
        blocked = np.zeros(gx.shape, dtype=bool)
        for _, geom in self.world.blocking_geometry():
            blocked |= shapely.contains_xy(geom, gx, gy)
        labels, _ = ndimage.label(~blocked)
        s = self.T_world_start
        i = int(np.clip(round((s.y - ymin) / res - 0.5), 0, len(ys) - 1))
        j = int(np.clip(round((s.x - xmin) / res - 0.5), 0, len(xs) - 1))
        reach = labels == labels[i, j] if labels[i, j] else ~blocked
        pts_world = np.column_stack([gx[reach], gy[reach]])
        self._true_free = self.T_map_world.transform_points(pts_world)
        self._true_free_area = float(len(pts_world) * res * res)
        return self._true_free

    def coverage(self) -> float:
        """Explored free area / true free area: the fraction of truly free, reachable cells the SLAM grid
        knows as free."""
        pts = self._true_free_cells()
        if not len(pts) or not self.cfg.slam.enabled:
            return 0.0
        grid = self.slam.occupancy_grid()
        if not grid.width:
            return 0.0
        rc = grid.world_to_cell(pts)
        ok = (rc[:, 0] >= 0) & (rc[:, 0] < grid.height) & (rc[:, 1] >= 0) & (rc[:, 1] < grid.width)
        vals = grid.data[rc[ok, 0], rc[ok, 1]]
        return float(np.count_nonzero((vals >= 0) & (vals < 50)) / len(pts))

    def sample_coverage(self) -> float:
        c = self.coverage()
        self.coverage_log.append((self.time, c))
        return c

    def coverage_summary(self) -> dict[str, Any]:
        """``coverage`` (final) and ``coverage_time_s``: when exploration ended (no reachable frontier left),
        or the last sample; plus when 90 % was first reached."""
        final = self.sample_coverage()
        t90 = next((t for t, c in self.coverage_log if c >= 0.9), None)
        done = getattr(self, "exploration_done_time", None)
        return {
            "coverage": round(final, 4),
            "coverage_time_s": round(done if done is not None else self.time, 2),
            "coverage_90_time_s": None if t90 is None else round(t90, 2),
            "true_free_area_m2": round(self._true_free_area or 0.0, 2),
            "exploration_complete": done is not None,
        }

    def objects_in_map(self) -> list:
        """The object map in the map frame. Seed mode keeps objects in ``odom``: like RViz with fixed frame
        ``map``, they are shown (and scored) through the current ``map → odom`` transform."""
        from dataclasses import replace

        T = self.T_map_odom
        return [replace(o, pose=T @ o.pose, frame_id="map") if o.frame_id == "odom" else o
                for o in self.consciousness.objects]

    def object_report(self):
        from app.ocslam.evaluation import evaluate_objects

        return evaluate_objects(
            self.objects_in_map(),
            self.truth_objects_map(),
            self.truth_obstacles_map(),
            self.cfg.consciousness.presence_threshold,
        )

    def summary(self) -> dict[str, Any]:
        sim_t = self.sim.time
        wall = self.wall_time_s or (time.perf_counter() - self.wall_start)
        out: dict[str, Any] = {
            "sim_time_s": round(sim_t, 3),
            "wall_time_s": round(wall, 3),
            "real_time_factor": round(sim_t / wall, 3) if wall > 0 else None,
            "distance_m": round(self._true_distance, 3),
            "world": self.world.name,
            "detector": self.cfg.detector.kind if self.detector is not None else "none",
            "consciousness_mode": self.cfg.consciousness.mode,
            "collisions": int(getattr(self.sim, "collisions", 0)),
        }
        out.update(self.metrics())
        out.update(self.odometry_errors())
        out.update(self.slam_metrics())
        if self.detector is not None:
            rep = self.object_report()
            d = rep.as_dict()
            out["objects"] = d
            for k in ("in_scene", "in_map", "tp", "fn", "fp_legs", "fp_corner", "fp_other", "precision_strict",
                      "precision_lenient", "recall", "pos_err_mean_m", "pos_err_max_m"):
                if k in d:
                    out[f"objects_{k}"] = d[k]
        out["stages_ms_per_sim_s"] = {k: round(v, 3) for k, v in self.timer.per_sim_second_ms(sim_t).items()}
        out["counters"] = {
            "scans": self.counters.scans,
            "images": self.counters.images,
            "detections": self.counters.detections,
            "fused_frames": self.counters.fused_frames,
            "skipped": dict(self.counters.skipped_frames),
            "errors": dict(self.counters.errors),
            "slam_skipped": dict(getattr(self.slam, "skipped", {})),
            "odometry_skipped": self.odometry.skipped,
        }
        if self.detector_error:
            out["detector_error"] = self.detector_error
        return out

    def metrics(self) -> dict[str, Any]:
        """How the loop runs (for the run summary and the Metrics panel): the camera renderer, the
        rendered camera size, whether the stages run in parallel, and each stage's recent ms per call."""
        w, h = self.camera_render_size()
        return {
            "renderer": self.renderer,
            "renderer_note": self.renderer_note,
            "camera_size": [w, h],
            "parallel_stages": self.jobs.parallel,
            "stages_recent_ms": {k: round(v, 3) for k, v in self.timer.recent_ms.items()},
        }

    def close(self) -> None:
        self.jobs.close()
        if self.camera_worker is not None:
            self.camera_worker.close()
            self.camera_worker = None
        self.sim.close()
