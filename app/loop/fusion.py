"""Camera frames of the loop: the detector job and the fusion job (the consciousness) of each frame.

:class:`CameraFusion` is a part of :class:`app.pipeline.Pipeline` (a mixin: it uses the pipeline's
``cfg``, ``sim``, ``jobs``, ``timer``, ``counters``, ``detector``, sensor buffers and estimators, all set up
in ``Pipeline.__init__``). The loop thread takes what a frame is fused with when the frame is processed;
the detector and the fusion run as :class:`~app.loop.stages.StageJobs`.
"""

from __future__ import annotations

import logging
import time
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Any

from app.ocslam.messages import Detections, Image
from app.ocslam.se2 import Pose2
from app.ocslam.sync import reproject_scan

log = logging.getLogger(__name__)


@dataclass
class FusionSnapshot:
    """What the last camera frame produced, for the UI and tests."""

    stamp: float = -1.0
    image: Image | None = None
    detections: Detections | None = None
    report: Any = None  # consciousness.FrameReport
    T_frame_base: Pose2 | None = None  # robot pose used for the fusion, in the objects' frame
    synced_scan_dt: float = 0.0  # |image stamp − scan stamp| used


class CameraFusion:
    """The detector and the consciousness on the camera frames (part of :class:`app.pipeline.Pipeline`)."""

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
        # the SLAM's lazy map update, when the fusion asks for the grid, is the SLAM's time (not the fusion's)
        self._map_update_s = 0.0
        t0 = time.perf_counter()
        try:
            self._fuse(dets, inputs, snap)
        except Exception:
            log.exception("consciousness failed on a frame; skipped")
            self.counters.error("consciousness")
        self.timer.add("consciousness", time.perf_counter() - t0 - self._map_update_s)
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
            grid = None
            if self.cfg.slam.enabled and c.corner_check:
                t_map = time.perf_counter()
                grid = slam.occupancy_grid()  # integrates the scans since the last call into the grid
                self._map_update_s = time.perf_counter() - t_map
                self.timer.charge("slam", self._map_update_s)
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
