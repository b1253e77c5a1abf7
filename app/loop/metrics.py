"""The run's metrics: the loop's own (renderer, stage times, counters) and the estimators against ground
truth (odometry and SLAM errors, map agreement, exploration coverage, the object map's precision and
recall), gathered in :meth:`RunMetrics.summary` (a headless run's ``summary.json``).

:class:`RunMetrics` is a part of :class:`app.pipeline.Pipeline` (a mixin: it reads the pipeline's
estimators, its ground-truth logs and the world's true geometry). Ground truth is read here and in the
overlay only, never by the estimators.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np


class RunMetrics:
    """Metrics of a run, for the summary, the benchmarks and the Metrics panel."""

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
