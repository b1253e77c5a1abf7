"""Record a live run as a rosbag2 MCAP bag (ROS 2 CDR messages with their definitions).

:class:`BagRecorder` observes a :class:`app.pipeline.Pipeline` from outside: after each loop step,
:meth:`BagRecorder.observe` reads the pipeline's public state (the latest odometry pose, the scan counter
and ``last_scan``, the camera frame and detections of the last fusion, the SLAM's map and graph) and
writes what is new. It changes nothing in the pipeline, except that building ``/map`` brings the SLAM's
lazy grid up to date, which the replay repeats at the same instants.

Topics, types and frames: :mod:`app.ros2.topics`. Example::

    rec = BagRecorder("runs/tour/bag")
    rec.start(pipe)
    while ...:
        pipe.step(); rec.observe(pipe)
    rec.close(pipe)
"""

from __future__ import annotations

import copy
import logging
import os
import queue
import threading
import time
from collections import deque
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError

from app.ros2 import convert, topics
from app.ros2.errors import RecordError
from app.ros2.typestore import ros2_typestore

if TYPE_CHECKING:
    from app.pipeline import Pipeline

log = logging.getLogger(__name__)

#: the bag's custom_data key naming its writer (the replay keeps the SLAM's grid updates in step with it)
WRITER_KEY = "ocslam.writer"
WRITER_VALUE = "ocslam-recorder-1"


def _qos(latched: bool) -> list[Qos]:
    zero = QosTime(0, 0)
    return [Qos(QosHistory.KEEP_LAST, 1 if latched else 10, QosReliability.RELIABLE,
                QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE, zero, zero,
                QosLiveliness.AUTOMATIC, zero, False)]


def static_transforms(robot_model: Any) -> list[tuple[str, str, np.ndarray]]:
    """``(parent, child, T_parent_child)`` of the robot's static frames, from its URDF link poses."""
    out = []
    for parent, child in topics.STATIC_FRAMES:
        T_bp = np.eye(4) if parent == "base_footprint" else np.asarray(robot_model.T_base(parent))
        T_bc = np.asarray(robot_model.T_base(child))
        out.append((parent, child, np.linalg.inv(T_bp) @ T_bc))
    return out


class BagRecorder:
    """Writes one run to ``path`` (a new bag folder: ``metadata.yaml`` + ``<name>_0.mcap``)."""

    def __init__(self, path: str | Path, *, image_format: str = "jpeg", jpeg_quality: int = 95,
                 map_hz: float = 1.0, cmd_vel_hz: float = 10.0, process: bool = True) -> None:
        self.path = Path(path)
        if self.path.exists():
            raise RecordError(f"{self.path} exists already: a bag is never overwritten (choose another --record path)")
        base = self.path.parent
        while not base.exists() and base != base.parent:
            base = base.parent
        if not base.is_dir() or not os.access(base, os.W_OK | os.X_OK):
            raise RecordError(f"cannot create bag {self.path}: {base} is not a writable directory")
        self.image_format = image_format
        self.jpeg_quality = int(jpeg_quality)
        self.map_period = 1.0 / map_hz
        self.cmd_period = 1.0 / cmd_vel_hz
        self.process = process
        self.counts: dict[str, int] = {}
        self.wall_s = 0.0  # time spent recording on the loop's thread (for the RTF cost)
        self.writer_cpu_s = 0.0  # CPU time of the writer process
        self._open = False
        self._last_odom = -1.0
        self._scans: int | None = None
        self._dets: Any = None
        self._snap: Any = None
        self._frames: deque | None = None  # (log time, frame, detections future) handed to the detector
        self._unhook: Any = None
        self._batch: list = []
        self._sink: Any = None
        self._results: queue.SimpleQueue = queue.SimpleQueue()
        self.errors = 0  # messages that could not be written
        self._next_map = 0.0
        self._next_cmd = 0.0

    # -- writing -----------------------------------------------------------------------------------
    def _write(self, topic: str, builder: str, args: tuple, t_log: float) -> None:
        """Queue one message: ``BUILDERS[builder](*args)`` makes it in the writer process (conversion, CDR
        and MCAP cost the loop only this call and the hand-over); ``args`` must not change afterwards."""
        self._batch.append((topic, builder, args, t_log))

    def _flush(self) -> None:
        while True:  # results taken on the estimator thread
            try:
                self._batch.extend(self._results.get_nowait())
            except queue.Empty:
                break
        if self._batch and self._sink is not None:
            self._sink.send(self._batch)  # one hand-over per batch
            self._batch = []

    # -- lifecycle ---------------------------------------------------------------------------------
    def start(self, pipe: Pipeline) -> BagRecorder:
        """Open the bag and write what is static: ``/tf_static`` and the ground truth."""
        t0 = time.perf_counter()
        custom = {WRITER_KEY: WRITER_VALUE}
        dt = getattr(getattr(pipe, "sim", None), "dt", None)
        if dt:
            custom[topics.STAMP_STEP_KEY] = repr(float(dt))
        self._sink = _ProcessSink(self.path, custom) if self.process else _ThreadSink(self.path, custom)
        self._open = True
        t = pipe.time
        self._write(topics.TF_STATIC, "tf_static", ([(t, p, c, T) for p, c, T in static_transforms(pipe.robot_model)],), t)
        try:
            gt = (pipe.truth_objects_map(), pipe.truth_obstacles_map(), t)
            self._write(topics.GT_OBJECTS, "gt_objects", gt, t)
            self._write(topics.GT_FOOTPRINTS, "gt_footprints", gt, t)
        except Exception as e:  # a world without ground truth still records
            log.warning("ground truth not recorded: %s", e)
        self._next_map = t + self.map_period
        self._scans = pipe.counters.scans
        self._snap = pipe.fusion
        self._dets = pipe.fusion.detections
        self._frames = deque() if self._hook_detector(pipe) else None
        self.wall_s += time.perf_counter() - t0
        return self

    def observe(self, pipe: Pipeline) -> None:
        """Write whatever the last step produced (call after each ``pipe.step()``)."""
        if not self._open:
            return
        t0 = time.perf_counter()
        t = pipe.time
        latest = pipe.odom_poses.latest()
        if latest is not None and latest[0] > self._last_odom:
            stamp, T = latest
            self._last_odom = stamp
            v, w = pipe.odometry.linear_x, pipe.odometry.angular_z
            self._write(topics.ODOM, "odom", (stamp, T, v, w), t)
            self._write(topics.TF, "tf", (stamp, "odom", "base_footprint", T), t)
        if self._scans is None:
            self._scans = pipe.counters.scans  # scans before the recording started are not written
        if pipe.counters.scans != self._scans and pipe.last_scan is not None:
            self._scans = pipe.counters.scans
            scan = pipe.last_scan
            self._write(topics.SCAN, "scan", (scan,), t)
            self._write(topics.EXACT_RANGES, "exact_ranges", (scan,), t)
            # map → odom as the loop publishes it now (a scan's own correction is published a period later)
            T_mo = pipe.T_map_odom
            self._write(topics.TF, "tf", (t, "map", "odom", T_mo), t)
            if pipe.truth_log and abs(pipe.truth_log[-1][0] - scan.stamp) < 1e-9:
                T_true = pipe.truth_log[-1][1]
                self._write(topics.GT_POSE, "pose", (scan.stamp, "map", T_true), t)
        self._observe_camera(pipe, t)
        if t + 1e-9 >= self._next_cmd and pipe.drive_mode != "idle":
            self._next_cmd = t + self.cmd_period
            cmd = pipe.cmd
            self._write(topics.CMD_VEL, "twist", (cmd,), t)
        if t + 1e-9 >= self._next_map:
            self._next_map += self.map_period * max(1, int((t - self._next_map) / self.map_period) + 1)
            self._write_results(pipe, t)
        if len(self._batch) >= 256:
            self._flush()
        self.wall_s += time.perf_counter() - t0

    def _hook_detector(self, pipe: Pipeline) -> bool:
        """See each camera frame when the loop hands it to the detector (``pipe.jobs.detect``): the frame
        and its detections' future, logged at that instant, the one the fusion's inputs are taken at."""
        jobs = getattr(pipe, "jobs", None)
        detect = getattr(jobs, "detect", None)
        if detect is None:
            return False

        def recorded_detect(fn: Any, frame: Any, *args: Any) -> Any:
            fut = detect(fn, frame, *args)
            if self._open:
                self._frames.append((pipe.time, frame, fut))
            return fut

        jobs.detect = recorded_detect
        self._unhook = lambda: setattr(jobs, "detect", detect)
        return True

    def _observe_camera(self, pipe: Pipeline, t: float) -> None:
        """Write the frames whose detections are ready, in the order they were taken."""
        if self._frames is None:  # no detector hook: the last fusion's frame, logged when seen
            snap = pipe.fusion
            if snap is not self._snap and snap.detections is not None and snap.detections is not self._dets:
                self._snap, self._dets = snap, snap.detections
                self._write_frame(pipe, t, snap.image, snap.detections)
            return
        while self._frames and self._frames[0][2].done():
            t_log, frame, fut = self._frames.popleft()
            try:
                dets = fut.result()
            except Exception:
                dets = None
            if dets is not None:  # None: the detector failed on it (the loop counted it)
                self._write_frame(pipe, t_log, getattr(frame, "image", None), dets)

    def _write_frame(self, pipe: Pipeline, t_log: float, img: Any, dets: Any) -> None:
        if img is not None:
            info = pipe.camera_model.info
            if (info.width, info.height) != (img.width, img.height):
                info = info.scaled(img.width, img.height)
            fmt, q = self.image_format, self.jpeg_quality
            self._write(topics.IMAGE_COMPRESSED, "image", (_stamped(img, dets.stamp), q, fmt), t_log)
            self._write(topics.CAMERA_INFO, "camera_info", (info, dets.stamp), t_log)
        self._write(topics.YOLO_BOXES, "yolo_boxes", (dets,), t_log)
        self._write(topics.EXACT_BOXES, "exact_boxes", (dets,), t_log)

    def _write_results(self, pipe: Pipeline, t: float) -> None:
        """``/map``, ``/objects``, ``/objects/markers`` and ``/slam/pose_graph`` at ``t``: taken on the
        estimator thread after the jobs already queued (``pipe.jobs.estimate``), so the loop never waits
        and the state is the one a sequential run has at ``t``."""
        estimate = getattr(getattr(pipe, "jobs", None), "estimate", None)
        if estimate is None:
            self._results_job(pipe, t, direct=True)
        else:
            estimate(self._results_job, pipe, t)

    def _results_job(self, pipe: Pipeline, t: float, direct: bool = False) -> None:
        out: list = []
        if pipe.cfg.slam.enabled:
            slam = pipe.slam  # on the estimator thread: no wait
            grid = slam.occupancy_grid()
            if grid.width and grid.height:
                out.append((topics.MAP, "map", (grid, t), t))
            graph = slam.pose_graph()
            out.append((topics.POSE_GRAPH, "pose_graph", (graph, t), t))
        if pipe.detector is not None:
            objs = [copy.copy(o) for o in pipe.objects_in_map()]
            thr = pipe.cfg.consciousness.presence_threshold
            out.append((topics.OBJECTS, "objects", (objs, t), t))
            out.append((topics.OBJECT_MARKERS, "object_markers", ([o for o in objs if o.presence >= thr], t), t))
        if direct:
            self._batch.extend(out)
        else:
            self._results.put(out)  # picked up by the loop thread's next flush

    def close(self, pipe: Pipeline | None = None) -> Path:
        """Write the final map, objects and graph (if ``pipe``) and finish the bag (``metadata.yaml``)."""
        if not self._open:
            return self.path
        t0 = time.perf_counter()
        try:
            if pipe is not None:
                wait = getattr(pipe, "wait_stages", None)
                if wait is not None:
                    wait()  # the detector's and the fusion's last frames
                self.observe(pipe)
                self._flush()
                self._write_results(pipe, pipe.time)
                if wait is not None:
                    wait()
        finally:
            if self._unhook is not None:
                self._unhook()
            self._open = False
            self._flush()
            if self._sink is not None:
                self.counts, self.errors = self._sink.close()
                self.writer_cpu_s = getattr(self._sink, "child_cpu_s", 0.0)
            self.wall_s += time.perf_counter() - t0
        return self.path


BUILDERS: dict[str, Any] = {
    "tf_static": lambda items: convert.tf_message([convert.transform_stamped(t, p, c, T) for t, p, c, T in items]),
    "gt_objects": lambda objs, obst, t: convert.ground_truth_to_ros(objs, obst, t)[0],
    "gt_footprints": lambda objs, obst, t: convert.ground_truth_to_ros(objs, obst, t)[1],
    "odom": convert.odom_to_ros,
    "tf": lambda t, parent, child, T: convert.tf_message([convert.transform_stamped(t, parent, child, T)]),
    "scan": convert.scan_to_ros,
    "exact_ranges": convert.exact_ranges_to_ros,
    "pose": convert.pose_stamped,
    "twist": convert.twist_to_ros,
    "image": convert.image_to_compressed,
    "camera_info": convert.camera_info_to_ros,
    "yolo_boxes": convert.yolo_boxes_to_ros,
    "exact_boxes": convert.exact_boxes_to_ros,
    "map": convert.grid_to_ros,
    "pose_graph": convert.pose_graph_markers,
    "objects": convert.objects_to_ros,
    "object_markers": convert.object_markers,
}


class _BagFile:
    """The MCAP bag itself: builds each message from its data and writes it (in the writer's process)."""

    def __init__(self, path: Path, custom: dict[str, str]) -> None:
        self.store = ros2_typestore()
        self.writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
        for k, v in custom.items():
            self.writer.set_custom_data(k, v)
        self.writer.open()
        self.conns: dict[str, Any] = {}
        self.counts: dict[str, int] = {}
        self.errors = 0

    def write(self, batch: list) -> None:
        for topic, builder, args, t_log in batch:
            try:
                msg = BUILDERS[builder](*args)
                conn = self.conns.get(topic)
                if conn is None:
                    conn = self.conns[topic] = self.writer.add_connection(
                        topic, topics.RECORDED_TOPICS[topic], typestore=self.store,
                        offered_qos_profiles=_qos(topic in topics.LATCHED_TOPICS))
                self.writer.write(conn, convert.to_ns(t_log), self.store.serialize_cdr(msg, msg.__msgtype__))
                self.counts[topic] = self.counts.get(topic, 0) + 1
            except Exception:  # one bad message never stops the recording
                log.exception("bag recorder: a %s message was not written", topic)
                self.errors += 1

    def close(self) -> tuple[dict[str, int], int]:
        self.writer.close()
        return self.counts, self.errors


def _open_bag(path: Path, custom: dict[str, str]) -> _BagFile:
    try:
        return _BagFile(path, custom)
    except (WriterError, OSError) as e:
        raise RecordError(f"cannot create bag {path}: {e}") from None


class _ThreadSink:
    """Writes on a thread of this process (shares the GIL with the loop)."""

    def __init__(self, path: Path, custom: dict[str, str]) -> None:
        self.bag = _open_bag(path, custom)
        self.q: queue.SimpleQueue = queue.SimpleQueue()
        self.thread = threading.Thread(target=self._run, name="ocslam-bag-writer", daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while (batch := self.q.get()) is not None:
            self.bag.write(batch)

    def send(self, batch: list) -> None:
        self.q.put(batch)

    def close(self) -> tuple[dict[str, int], int]:
        self.q.put(None)
        self.thread.join()
        return self.bag.close()


def _writer_process(conn: Any, q: Any, path: str, custom: dict[str, str]) -> None:
    try:
        bag = _open_bag(Path(path), custom)
    except Exception as e:
        conn.send(("error", str(e)))
        return
    conn.send(("ok", ""))
    t_cpu = time.process_time()
    while (batch := q.get()) is not None:
        bag.write(batch)
    counts, errors = bag.close()
    conn.send((counts, errors, time.process_time() - t_cpu))


class _ProcessSink:
    """Writes in a child process (spawned: never fork a process holding pybullet): the loop only queues
    the data (a feeder thread pickles it into the pipe), and the conversion, CDR and MCAP work runs in
    the child, on the other core."""

    def __init__(self, path: Path, custom: dict[str, str]) -> None:
        import multiprocessing as mp

        ctx = mp.get_context("spawn")
        self.conn, child = ctx.Pipe()
        self.q = ctx.Queue()
        self.proc = ctx.Process(target=_writer_process, args=(child, self.q, str(path), custom),
                                name="ocslam-bag-writer", daemon=True)
        self.proc.start()
        child.close()
        self.child_cpu_s = 0.0  # the child starts while the run goes on: its "ok" is read at close

    def send(self, batch: list) -> None:
        self.q.put(batch)

    def close(self) -> tuple[dict[str, int], int]:
        self.q.put(None)
        status, msg = self.conn.recv() if self.proc.is_alive() or self.conn.poll() else ("error", "writer process died")
        if status != "ok":
            self.proc.join(timeout=5)
            raise RecordError(msg)
        counts, errors, self.child_cpu_s = self.conn.recv()
        self.q.close()
        self.q.join_thread()
        self.proc.join(timeout=30)
        return counts, errors


def _stamped(img: Any, stamp: float) -> Any:
    from dataclasses import replace

    return img if img.stamp == stamp else replace(img, stamp=stamp)


def attach(pipe: Pipeline, path: str | Path, **kwargs: Any) -> BagRecorder:
    """Start a recorder on ``pipe`` and make every ``pipe.step()`` feed it (the live web app's hook).

    The instance's ``step`` is wrapped; :func:`detach` (or ``pipe.close``) restores it."""
    rc = getattr(pipe.cfg, "replay", None)
    if rc is not None:
        kwargs.setdefault("image_format", rc.record_image_format)
        kwargs.setdefault("jpeg_quality", rc.record_jpeg_quality)
    rec = BagRecorder(path, **kwargs).start(pipe)
    step = pipe.step

    def recorded_step() -> None:
        step()
        try:
            rec.observe(pipe)
        except Exception:  # never lose the loop for the recording
            log.exception("bag recording failed; recording stopped")
            rec._open = False

    pipe.step = recorded_step  # type: ignore[method-assign]
    rec._restore = lambda: setattr(pipe, "step", step)  # type: ignore[attr-defined]
    return rec


def detach(pipe: Pipeline, rec: BagRecorder) -> Path:
    """Stop recording: restore ``pipe.step`` and finish the bag."""
    restore = getattr(rec, "_restore", None)
    if restore is not None:
        restore()
    return rec.close(pipe)


def staging_path(out: str | Path) -> Path:
    """Where a run directory's bag is written while the run lasts: ``.<name>.bag-recording/bag`` beside
    ``out`` (the run directory is written as a unit at the end, :func:`app.session.write_run_dir`); moved
    in as ``out/bag`` by :func:`move_into_run_dir`."""
    import shutil

    out = Path(out).absolute()
    stage = out.parent / f".{out.name}.bag-recording"
    if stage.exists():
        shutil.rmtree(stage)  # left by a run that was killed before its bag was moved in
    stage.mkdir(parents=True)
    return stage / "bag"


def move_into_run_dir(rec: BagRecorder, out: str | Path) -> Path:
    """Move a finished bag into the run directory as ``out/bag`` (replacing an older one)."""
    import shutil

    dst = Path(out) / "bag"
    if dst.exists():
        shutil.rmtree(dst)
    src = rec.path
    src.replace(dst)
    if src.parent.name.endswith(".bag-recording"):
        shutil.rmtree(src.parent, ignore_errors=True)
    rec.path = dst
    return dst
