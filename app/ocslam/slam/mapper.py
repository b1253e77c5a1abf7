"""The :class:`Slam` facade: front end (scan-to-local-map matching), keyframes, loops, graph, map.

Per scan (``process``):

1. Validate the scan; bad ones are skipped and counted in ``skipped``.
2. Predict ``T_map_base`` from the last estimate and the odometry increment.
3. Match the scan against the *local map* (the last ``local_map_keyframes`` keyframes' returns): branch
   and bound over ``±match_search_xy_m × ±match_search_yaw_rad`` around the prediction, then Gauss–Newton
   point-to-line refinement with the prediction as a weak prior.
4. Record the scan's pose relative to the current keyframe (so optimisation moves it too).
5. After ``keyframe_distance_m`` or ``keyframe_heading_rad`` of motion the scan becomes a keyframe: a
   graph node with a sequential edge, the local map is rebuilt, and loops are searched
   (:mod:`app.ocslam.slam.loop`). New loop edges trigger a sparse optimisation (:mod:`.graph`) at most
   every ``optimize_every_keyframes`` keyframes; ``correction_count`` then increments.

The occupancy grid is brought up to date lazily in :meth:`Slam.occupancy_grid`: new keyframes are ray
cast into it, and keyframes that an optimisation moved are removed at their old pose and re-inserted at
the new one (at most ``map_update_budget`` per call, largest moves first), so the map follows the
corrected poses without full rebuilds.
"""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
from numpy.typing import NDArray

from app.ocslam.config import SlamConfig
from app.ocslam.messages import LaserScan, OccupancyGrid
from app.ocslam.se2 import Pose2, between, compose, interpolate, transform_points, wrap_angle
from app.ocslam.slam.field import MatchField, build_field
from app.ocslam.slam.graph import PoseGraph, as_full_info, edge_chi2, edge_errors, optimize
from app.ocslam.slam.grid import LogOddsGrid
from app.ocslam.slam.information import odometry_information, scan_information
from app.ocslam.slam.keyframes import Growable, Keyframes, KeyframeScan, Trajectory
from app.ocslam.slam.loop import LoopCloser
from app.ocslam.slam.matcher import RefineResult, correlative_search, line_hessian, refine
from app.ocslam.slam.scan_input import check_scan, scan_geometry
from app.ocslam.slam.verify import Candidate, LoopVerifier


class Slam:
    """Online 2D graph SLAM on ``LaserScan`` + wheel odometry. See the module docstring.

    Frames: ``map`` (equal to ``odom`` at start), ``odom``, ``base`` (the robot, ``T_odom_base`` from
    odometry) and the scanner ``T_base_scan``.
    """

    def __init__(self, cfg: SlamConfig | None = None, T_base_scan: Pose2 = Pose2()) -> None:
        self.cfg = cfg if cfg is not None else SlamConfig()
        self.T_base_scan = T_base_scan
        self.keyframes = Keyframes()
        self.traj = Trajectory()
        self.edges_ij = Growable((2,), np.int64)
        self.edges_z = Growable((3,))
        self.edges_info = Growable((3, 3))
        self.edges_loop = Growable((), bool)
        self.edges_active = Growable((), bool)
        self.loops = LoopCloser(self.cfg)
        self.verifier = LoopVerifier(self.cfg)
        self._kf_odom = Growable((3,))  # T_odom_base at each keyframe
        self._match_H = (np.zeros((3, 3)), 0.0)  # (Hessian in the map frame, yaw) of the last match
        self.correction_count = 0
        self.skipped: dict[str, int] = Counter()
        self.stats: dict[str, int] = Counter()
        self._beams: int | None = None
        self._last_stamp = -math.inf
        self._last_pose: NDArray[np.float64] | None = None  # T_map_base of the last processed scan
        self._last_odom: NDArray[np.float64] | None = None
        self._field: MatchField | None = None
        self._field_kf = -1  # newest keyframe in the local map
        self._pending_loops = 0
        self._kf_since_opt = 0
        self._grid = LogOddsGrid(self.cfg.resolution_m, self.cfg.log_odds_hit, self.cfg.log_odds_miss, self.cfg.log_odds_clamp)
        self._inserted = Growable((3,))  # pose each keyframe was inserted into the grid at (NaN: not yet)
        self._traj_cache: tuple[int, int, NDArray[np.float64]] | None = None

    def process(self, scan: LaserScan, T_odom_base: Pose2) -> bool:
        """Process one scan with the wheel odometry at its stamp. Returns True if it became a keyframe."""
        odom = np.asarray(T_odom_base.as_array() if isinstance(T_odom_base, Pose2) else T_odom_base, np.float64)
        reason = check_scan(scan, odom, self._last_stamp, self._beams)
        if reason is not None:
            self.skipped[reason] += 1
            return False
        self._beams = len(scan.ranges)
        self._last_stamp = float(scan.stamp)
        cfg = self.cfg
        if self._last_pose is None or self._last_odom is None:
            pred = odom.copy()  # map = odom at start
        else:
            pred = compose(self._last_pose, between(self._last_odom, odom))
        if not cfg.enabled:
            self._record(scan.stamp, pred, odom, anchor=-1)
            return False
        geo = scan_geometry(scan, cfg, self.T_base_scan)
        nk = len(self.keyframes)
        if len(geo.points) < cfg.min_points:
            self.skipped["too_few_returns"] += 1
            self._record(scan.stamp, pred, odom)
            return False
        if nk == 0:
            self._record(scan.stamp, pred, odom)
            self._add_keyframe(scan.stamp, pred, geo)
            return True
        pose = self._match(geo.points, pred)
        self._record(scan.stamp, pose, odom)
        kp = self.keyframes.poses.data[-1]
        if (
            math.hypot(pose[0] - kp[0], pose[1] - kp[1]) >= cfg.keyframe_distance_m
            or abs(float(wrap_angle(pose[2] - kp[2]))) >= cfg.keyframe_heading_rad
        ):
            self._add_keyframe(scan.stamp, pose, geo)
            return True
        return False

    # ------------------------------------------------------------------------------------------
    # front end
    # ------------------------------------------------------------------------------------------
    def _match(self, pts: NDArray[np.float64], pred: NDArray[np.float64]) -> NDArray[np.float64]:
        """Scan-to-local-map pose ``T_map_base`` of ``pts`` (base frame) near the prediction ``pred``.

        Branch-and-bound search over the window around the prediction, then Gauss–Newton refinement from
        its optimum. With ``match_direct_min_inliers < 1`` a refinement straight from the prediction is
        tried first and kept when that fraction of the points fits the map's surfaces (cheaper, but it
        can settle in a local minimum when the predicted heading is off by a degree or more).
        """
        cfg = self.cfg
        self._match_H = (np.zeros((3, 3)), float(pred[2]))
        fld = self._local_field()
        if fld is None:
            return pred
        prior_info = np.array([1 / cfg.prior_sigma_xy_m**2, 1 / cfg.prior_sigma_xy_m**2, 1 / cfg.prior_sigma_yaw_rad**2])

        def refine_from(init: NDArray[np.float64]) -> RefineResult:
            return refine(fld, pts, init, prior=pred, prior_info=prior_info, max_dist_m=4 * cfg.match_resolution_m,
                          robust_m=cfg.match_robust_m, point_weight=cfg.match_point_weight)

        direct = None
        if cfg.match_direct_min_inliers < 1.0:
            direct = refine_from(pred)
            if direct.inlier_fraction >= cfg.match_direct_min_inliers:
                self.stats["match_direct"] += 1
                self._match_H = (line_hessian(direct), float(direct.pose[2]))
                return direct.pose
        res = correlative_search(
            fld, pts, pred, cfg.match_search_xy_m, cfg.match_search_yaw_rad, cfg.match_yaw_step_rad, cfg.match_min_score
        )
        if res is None:
            self.stats["match_failed"] += 1
            if direct is not None and direct.inlier_fraction > 0:
                self._match_H = (line_hessian(direct), float(direct.pose[2]))
                return direct.pose
            return pred
        ref = refine_from(res.pose)
        self.stats["match_searched"] += 1
        if direct is not None and direct.inlier_fraction > ref.inlier_fraction:
            ref = direct
        self._match_H = (line_hessian(ref), float(ref.pose[2]))
        return ref.pose

    def _local_field(self) -> MatchField | None:
        nk = len(self.keyframes)
        if self._field is not None and self._field_kf == nk - 1:
            return self._field
        cfg = self.cfg
        first = max(0, nk - cfg.local_map_keyframes)
        poses = self.keyframes.poses.data
        pts = [transform_points(poses[i], self.keyframes.scans[i].points) for i in range(first, nk)]
        self._field = build_field(
            np.vstack(pts),
            cfg.match_resolution_m,
            cfg.match_sigma_m,
            margin_m=cfg.match_search_xy_m + 0.5,
            center=poses[-1, :2],
            half_size_m=cfg.local_map_half_size_m,
        )
        self._field_kf = nk - 1
        return self._field

    def _record(self, stamp: float, pose: NDArray[np.float64], odom: NDArray[np.float64], anchor: int | None = None) -> None:
        k = len(self.keyframes) - 1 if anchor is None else anchor
        rel = between(self.keyframes.poses.data[k], pose) if k >= 0 else pose
        self.traj.add(float(stamp), k, rel, odom)
        self._last_pose = np.asarray(pose, np.float64).copy()
        self._last_odom = odom.copy()

    # ------------------------------------------------------------------------------------------
    # keyframes, loops, optimisation
    # ------------------------------------------------------------------------------------------
    def _add_edge(self, i: int, j: int, z: NDArray[np.float64], info: NDArray[np.float64], loop: bool) -> None:
        self.edges_ij.append((i, j))
        self.edges_z.append(z)
        info = np.asarray(info, np.float64)
        self.edges_info.append(info if info.shape == (3, 3) else np.diag(info.reshape(3)))
        self.edges_loop.append(loop)
        self.edges_active.append(True)

    def _active_edges(self):
        a = self.edges_active.data
        return self.edges_ij.data[a], self.edges_z.data[a], self.edges_info.data[a], self.edges_loop.data[a]

    def sequential_information(self, H_map: NDArray[np.float64], yaw: float, odom_delta: NDArray[np.float64]) -> NDArray[np.float64]:
        """``(3, 3)`` information of a sequential edge: the matcher's (clamped) plus the odometry's.

        Where the scan constrains a direction (walls across it) the matcher's information dominates; along
        a corridor's axis it is at the floor and the odometry increment's information takes over.
        """
        cfg = self.cfg
        scan = scan_information(H_map, yaw, cfg.match_info_point_sigma_m, cfg.edge_sigma_xy_m, cfg.edge_sigma_yaw_rad, cfg.match_info_floor)
        odo = odometry_information(odom_delta, cfg.odom_sigma_xy_per_m, cfg.odom_sigma_yaw_per_rad, cfg.odom_sigma_xy_m, cfg.odom_sigma_yaw_rad)
        return scan + odo

    def _add_keyframe(self, stamp: float, pose: NDArray[np.float64], geo: KeyframeScan) -> None:
        cfg = self.cfg
        k = self.keyframes.add(float(stamp), pose, geo)
        self._inserted.append(np.full(3, np.nan))
        odom = self.traj.odom.data[-1].copy()
        self._kf_odom.append(odom)
        # the scan that made the keyframe is now anchored on it
        self.traj.anchor.data[-1] = k
        self.traj.rel.data[-1] = 0.0
        if k > 0:
            prev = self.keyframes.poses.data[k - 1]
            H, yaw = self._match_H
            info = self.sequential_information(H, yaw, between(self._kf_odom.data[k - 1], odom))
            self._add_edge(k - 1, k, between(prev, pose), info, False)
        self._kf_since_opt += 1
        if cfg.loop_closure and k > 0:
            poses = self.keyframes.poses.data
            for lc in self.loops.search(self.keyframes, k):
                info = lc.info if lc.info is not None else np.diag([1 / cfg.loop_sigma_xy_m**2, 1 / cfg.loop_sigma_xy_m**2, 1 / cfg.loop_sigma_yaw_rad**2])
                cand = Candidate(lc.anchor, lc.keyframe, lc.measurement, info, lc.score)
                if lc.contradiction is not None and lc.contradiction.worst > cfg.loop_max_contradiction:
                    # the aligned query puts walls where the submap saw free space (or sees through its
                    # walls): a place that only looks like the old one locally
                    self.verifier.reject(cand, "free_space")
                    continue
                ij, z, inf, _ = self._active_edges()
                for c in self.verifier.offer(cand, poses, ij, z, inf):
                    self._add_edge(c.anchor, c.keyframe, c.z, c.info, True)
                    self._pending_loops += 1
                    self.loops.travel_since_loop = 0.0
            self.verifier.expire(k)
        if self._pending_loops and self._kf_since_opt >= cfg.optimize_every_keyframes:
            self.optimize()

    def optimize(self, iterations: int | None = None) -> bool:
        """Optimise the pose graph now (``optimize_iterations`` by default). Returns True if keyframes moved."""
        iterations = self.cfg.optimize_iterations if iterations is None else iterations
        self._pending_loops = 0
        self._kf_since_opt = 0
        if len(self.keyframes) < 2 or len(self.edges_ij) == 0:
            return False
        poses = self.keyframes.poses.data
        cfg = self.cfg
        x = poses
        for _round in range(3):
            act = np.flatnonzero(self.edges_active.data)
            ij, z, info, loop = (self.edges_ij.data[act], self.edges_z.data[act], self.edges_info.data[act], self.edges_loop.data[act])
            res = optimize(x, ij, z, info, loop, robust_scale=cfg.loop_robust_scale, iterations=iterations)
            if not np.all(np.isfinite(res.poses)):
                break
            x = res.poses
            # verification after the optimisation: loop edges the rest of the graph contradicts go
            chi2 = edge_chi2(edge_errors(res.poses, ij, z), info)
            bad = act[loop & (chi2 > cfg.loop_residual_chi2)]
            if len(bad) == 0:
                break
            for m in bad:
                self.edges_active.data[m] = False
                a, b = self.edges_ij.data[m]
                self.verifier.rejected.append((int(a), int(b), "residual"))
                self.verifier.rejected_by["residual"] += 1
        d = res.poses - poses
        if not np.all(np.isfinite(res.poses)):
            self.stats["optimize_failed"] += 1
            return False
        moved = float(np.max(np.abs(d[:, :2]))) > 1e-4 or float(np.max(np.abs(wrap_angle(d[:, 2])))) > 1e-5
        poses[:] = res.poses
        self.stats["optimizations"] += 1
        if moved:
            self.correction_count += 1
            self._field = None
            # carry the tracking estimate along with its keyframe
            k = int(self.traj.anchor.data[-1]) if len(self.traj) else -1
            if k >= 0:
                self._last_pose = compose(poses[k], self.traj.rel.data[-1])
        return moved

    # ------------------------------------------------------------------------------------------
    # outputs
    # ------------------------------------------------------------------------------------------
    @property
    def T_map_odom(self) -> Pose2:
        """The ``map → odom`` correction (identity until the estimate departs from odometry)."""
        if self._last_pose is None or self._last_odom is None:
            return Pose2()
        return Pose2.from_array(compose(self._last_pose, between(self._last_odom, np.zeros(3))))

    def _poses(self) -> NDArray[np.float64]:
        """Cached corrected poses (recomputed after new scans or a correction)."""
        n = len(self.traj)
        key = (n, self.correction_count)
        if self._traj_cache is None or self._traj_cache[:2] != key:
            self._traj_cache = (n, self.correction_count, self.traj.poses(self.keyframes.poses.data))
        return self._traj_cache[2]

    def trajectory(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(N,)`` stamps and ``(N, 3)`` corrected ``T_map_base`` of every processed scan."""
        return self.traj.stamps.data.copy(), self._poses().copy()

    def pose_at(self, stamp: float) -> Pose2:
        """``T_map_base`` at ``stamp``, interpolated between processed scans (clamped at the ends)."""
        if len(self.traj) == 0:
            return Pose2()
        stamps = self.traj.stamps.data
        i = int(np.clip(np.searchsorted(stamps, stamp, side="right") - 1, 0, max(len(stamps) - 2, 0)))
        j = min(i + 2, len(stamps))
        return Pose2.from_array(interpolate(float(stamp), stamps[i:j], self._poses()[i:j]))

    def keyframe_pose(self, k: int) -> Pose2:
        """Current (optimised) ``T_map_kf`` of keyframe ``k``."""
        return Pose2.from_array(self.keyframes.poses.data[k])

    def keyframe_at(self, stamp: float) -> int | None:
        """The keyframe the processed scan nearest in time to ``stamp`` is anchored to (None before any)."""
        if len(self.keyframes) == 0 or len(self.traj) == 0:
            return None
        st = self.traj.stamps.data
        i = int(np.clip(np.searchsorted(st, stamp), 0, len(st) - 1))
        if i > 0 and abs(st[i - 1] - stamp) <= abs(st[i] - stamp):
            i -= 1
        k = int(self.traj.anchor.data[i])
        return k if k >= 0 else None

    def pose_graph(self) -> PoseGraph:
        """The graph for display: active edges (``is_loop`` marks accepted loop closures) and the
        ``rejected`` loop closures ``(R, 2)`` (verification or post-optimisation residual)."""
        act = self.edges_active.data
        rej = np.array([(a, b) for a, b, _ in self.verifier.rejected], np.int64).reshape(-1, 2)
        return PoseGraph(
            nodes=self.keyframes.poses.data.copy(),
            stamps=self.keyframes.stamps.data.copy(),
            edges=self.edges_ij.data[act].copy(),
            is_loop=self.edges_loop.data[act].copy(),
            rejected=rej,
        )

    def metrics(self) -> dict:
        """Counters for the metrics panel and reports: keyframes, loop closures accepted / rejected (by reason)."""
        act = self.edges_active.data
        loop = self.edges_loop.data
        rej = dict(self.verifier.rejected_by)
        return {
            "slam_keyframes": int(len(self.keyframes)),
            "slam_loops_accepted": int((loop & act).sum()),
            "slam_loops_rejected": int(sum(rej.values())),
            "slam_loops_pending": int(len(self.verifier.pending)),
            "slam_loops_rejected_by": rej,
            "slam_loop_candidates": int(self.loops.accepted),
            "slam_loops_ambiguous": int(self.loops.ambiguous),
            "slam_corrections": int(self.correction_count),
        }

    def _insert(self, k: int, pose: NDArray[np.float64], sign: float) -> None:
        sc = self.keyframes.scans[k]
        T = Pose2.from_array(pose)
        self._grid.scan_update(T.transform_points(sc.sensor)[0], T.transform_points(sc.ends), sc.hit, sign)

    def update_map(self, budget: int | None = None) -> int:
        """Bring the grid up to date with the keyframes (see the module docstring). Returns keyframes touched."""
        budget = self.cfg.map_update_budget if budget is None else budget
        poses = self.keyframes.poses.data
        ins = self._inserted.data
        new = np.isnan(ins[:, 0])
        d = np.where(new[:, None], 0.0, poses - np.nan_to_num(ins))
        tol_xy = 0.5 * self.cfg.resolution_m
        tol_yaw = 0.5 * self.cfg.resolution_m / max(self.cfg.free_clear_range_m, 1.0)
        moved = ~new & ((np.hypot(d[:, 0], d[:, 1]) > tol_xy) | (np.abs(wrap_angle(d[:, 2])) > tol_yaw))
        todo = np.flatnonzero(new)
        mv = np.flatnonzero(moved)
        mv = mv[np.argsort(-np.hypot(d[mv, 0], d[mv, 1]))]
        order = np.concatenate([todo, mv])[:budget]
        for k in order:
            k = int(k)
            if not np.isnan(ins[k, 0]):
                self._insert(k, ins[k], -1.0)
            self._insert(k, poses[k], 1.0)
            ins[k] = poses[k]
        return len(order)

    def occupancy_grid(self, budget: int | None = None) -> OccupancyGrid:
        """The map (``-1`` unknown, ``0..100``) in the ``map`` frame, updated first (bounded work per call)."""
        self.update_map(budget)
        stamp = float(self.traj.stamps.data[-1]) if len(self.traj) else 0.0
        return self._grid.to_msg(stamp)

    # ------------------------------------------------------------------------------------------
    # save / load
    # ------------------------------------------------------------------------------------------
    def state_dict(self) -> dict:
        """Everything needed to continue mapping later: numpy arrays and small lists/scalars."""
        scans = self.keyframes.scans
        npts = np.array([len(s.points) for s in scans], np.int64)
        nends = np.array([len(s.ends) for s in scans], np.int64)
        return {
            "version": 2,
            "T_base_scan": np.array(list(self.T_base_scan)),
            "kf_poses": self.keyframes.poses.data.copy(),
            "kf_stamps": self.keyframes.stamps.data.copy(),
            "kf_npoints": npts,
            "kf_points": np.vstack([s.points for s in scans]) if scans else np.zeros((0, 2)),
            "kf_nends": nends,
            "kf_ends": np.vstack([s.ends for s in scans]) if scans else np.zeros((0, 2)),
            "kf_hit": np.concatenate([s.hit for s in scans]) if scans else np.zeros(0, bool),
            "kf_sensor": np.array([s.sensor for s in scans]).reshape(-1, 2),
            "edges_ij": self.edges_ij.data.copy(),
            "edges_z": self.edges_z.data.copy(),
            "edges_info": self.edges_info.data.copy(),
            "edges_loop": self.edges_loop.data.copy(),
            "edges_active": self.edges_active.data.copy(),
            "kf_odom": self._kf_odom.data.copy(),
            "loops_rejected": np.array([(a, b) for a, b, _ in self.verifier.rejected], np.int64).reshape(-1, 2),
            "loops_rejected_reason": [r for _, _, r in self.verifier.rejected],
            "traj_stamps": self.traj.stamps.data.copy(),
            "traj_anchor": self.traj.anchor.data.copy(),
            "traj_rel": self.traj.rel.data.copy(),
            "traj_odom": self.traj.odom.data.copy(),
            "beams": -1 if self._beams is None else int(self._beams),
            "correction_count": int(self.correction_count),
            "skipped": dict(self.skipped),
            "stats": dict(self.stats),
        }

    @classmethod
    def from_state_dict(cls, cfg: SlamConfig, d: dict) -> Slam:
        """Rebuild a :class:`Slam` from :meth:`state_dict` output; mapping continues where it stopped."""
        s = cls(cfg, Pose2.from_array(d["T_base_scan"]))
        npts = np.asarray(d["kf_npoints"], np.int64)
        nends = np.asarray(d["kf_nends"], np.int64)
        po = np.concatenate([[0], np.cumsum(npts)])
        eo = np.concatenate([[0], np.cumsum(nends)])
        pts, ends, hit = np.asarray(d["kf_points"]), np.asarray(d["kf_ends"]), np.asarray(d["kf_hit"], bool)
        sensor = np.asarray(d["kf_sensor"]).reshape(-1, 2)
        for k, (pose, st) in enumerate(zip(np.asarray(d["kf_poses"]).reshape(-1, 3), np.asarray(d["kf_stamps"]))):
            scan = KeyframeScan(pts[po[k] : po[k + 1]].copy(), ends[eo[k] : eo[k + 1]].copy(), hit[eo[k] : eo[k + 1]].copy(), sensor[k].copy())
            s.keyframes.add(float(st), pose, scan)
            s._inserted.append(np.full(3, np.nan))
        eij = np.asarray(d["edges_ij"]).reshape(-1, 2)
        info = as_full_info(np.asarray(d["edges_info"]))  # (M, 3) diagonal in version-1 states
        active = np.asarray(d.get("edges_active", np.ones(len(eij), bool)), bool).reshape(-1)
        for m, (ij, z, lp) in enumerate(zip(eij, np.asarray(d["edges_z"]).reshape(-1, 3), np.asarray(d["edges_loop"]).reshape(-1))):
            s._add_edge(int(ij[0]), int(ij[1]), z, info[m], bool(lp))
            s.edges_active.data[-1] = bool(active[m])
        reasons = list(d.get("loops_rejected_reason", []))
        for n, (a, b) in enumerate(np.asarray(d.get("loops_rejected", np.zeros((0, 2))), np.int64).reshape(-1, 2)):
            r = str(reasons[n]) if n < len(reasons) else "rejected"
            s.verifier.rejected.append((int(a), int(b), r))
            s.verifier.rejected_by[r] += 1
        s.traj.stamps = Growable.from_array(np.asarray(d["traj_stamps"], np.float64).reshape(-1))
        s.traj.anchor = Growable.from_array(np.asarray(d["traj_anchor"], np.int64).reshape(-1))
        s.traj.rel = Growable.from_array(np.asarray(d["traj_rel"], np.float64).reshape(-1, 3))
        s.traj.odom = Growable.from_array(np.asarray(d["traj_odom"], np.float64).reshape(-1, 3))
        if "kf_odom" in d:
            s._kf_odom = Growable.from_array(np.asarray(d["kf_odom"], np.float64).reshape(-1, 3))
        else:  # version 1: the odometry of the scan that made each keyframe
            anch = s.traj.anchor.data
            for k in range(len(s.keyframes)):
                hits = np.flatnonzero(anch == k)
                s._kf_odom.append(s.traj.odom.data[hits[0]] if len(hits) else np.zeros(3))
        beams = int(d.get("beams", -1))
        s._beams = None if beams < 0 else beams
        s.correction_count = int(d.get("correction_count", 0))
        s.skipped.update({str(k): int(v) for k, v in dict(d.get("skipped", {})).items()})
        s.stats.update({str(k): int(v) for k, v in dict(d.get("stats", {})).items()})
        if len(s.traj):
            s._last_stamp = float(s.traj.stamps.data[-1])
            s._last_pose = s.traj.poses(s.keyframes.poses.data)[-1].copy()
            s._last_odom = s.traj.odom.data[-1].copy()
        return s
