"""Frontier-based autonomous exploration.

:class:`FrontierExplorer` picks where to go: every frontier cluster (:mod:`.frontiers`) gets an *approach
cell*, the reachable, observed, unblocked cell within ``approach_radius_m`` of one of its cells (and in
line of sight of it) with the cheapest path from the robot (one Dijkstra search ranks them all). Its cost is ``path cost − gain_weight ×
frontier length``; the cheapest wins. Frontiers without a reachable approach cell (behind walls, in
narrow gaps, outside the apartment seen through an opening too small for the robot) are skipped, and
so are approach cells near blacklisted points (goals that failed or were reached without clearing
their frontier). Unknown cells may be crossed at ``unknown_cost`` times the normal cost, so frontiers
in the middle of big rooms (beyond the LIDAR's range) are handled like any other.

Against oscillation: the current goal is kept while it stays valid (still next to a frontier,
reachable, not blacklisted) unless another frontier becomes cheaper by more than ``switch_margin_m``; a
goal whose frontier vanishes while the robot is within ``visit_radius_m`` counts as visited
(blacklisted), and a place given up ``max_abandons`` times for other goals (a frontier that flickers
in a noisy map) is blacklisted too.

:class:`ExplorationController` drives the loop: it asks the explorer for a goal whenever the map
changes (at most every ``replan_period_s``), follows the path with a :class:`~.follower.PathFollower`,
blacklists goals it cannot reach (no progress, blocked too often) and declares exploration done when
no reachable frontier is left on several consecutive maps.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from app.ocslam.config import RobotConfig
from app.ocslam.messages import LaserScan, OccupancyGrid, Twist
from app.ocslam.navigation.astar import cost_to_go, extract_path, local_to_xy, smooth_path
from app.ocslam.navigation.costmap import OCCUPIED_THRESHOLD, CostMap, build_costmap
from app.ocslam.navigation.follower import ARRIVED, BLOCKED, PathFollower, StuckDetector
from app.ocslam.navigation.frontiers import (
    FRONTIER_FREE_THRESHOLD,
    Frontier,
    frontiers_from_labels,
    label_frontiers,
)
from app.ocslam.se2 import Pose2


class FrontierExplorer:
    """Choose the next exploration goal on the SLAM grid (all points in the ``map`` frame)."""

    def __init__(
        self,
        robot_radius_m: float,
        *,
        min_frontier_size: int = 5,
        blacklist_radius_m: float = 0.5,
        approach_radius_m: float | None = None,
        gain_weight: float = 0.5,
        unknown_cost: float = 3.0,
        switch_margin_m: float = 1.0,
        keep_slack_m: float = 0.3,
        goal_clearance_m: float = 0.12,
        inflation_padding_m: float = 0.025,
        visit_radius_m: float = 0.6,
        max_abandons: int = 3,
        clearance_m: float = 0.3,
        clearance_weight: float = 3.0,
        occupied_threshold: int = OCCUPIED_THRESHOLD,
        free_threshold: int = FRONTIER_FREE_THRESHOLD,
    ) -> None:
        self.robot_radius_m = float(robot_radius_m)
        self.min_frontier_size = int(min_frontier_size)
        self.blacklist_radius_m = float(blacklist_radius_m)
        self.approach_radius_m = float(
            approach_radius_m if approach_radius_m is not None else max(0.3, 2.5 * robot_radius_m)
        )
        self.gain_weight = float(gain_weight)
        self.unknown_cost = float(unknown_cost)
        self.switch_margin_m = float(switch_margin_m)
        self.keep_slack_m = float(keep_slack_m)
        self.goal_clearance_m = float(goal_clearance_m)
        self.inflation_padding_m = float(inflation_padding_m)
        self.visit_radius_m = float(visit_radius_m)
        self.max_abandons = int(max_abandons)
        self._abandoned: list[list] = []  # [point (2,), count]
        self.clearance_m = float(clearance_m)
        self.clearance_weight = float(clearance_weight)
        self.occupied_threshold = int(occupied_threshold)
        self.free_threshold = int(free_threshold)
        self.blacklist: list[NDArray[np.float64]] = []
        self.virtual_obstacles: list[NDArray[np.float64]] = []  # (K, 2) point sets, map frame
        self.goal_xy: NDArray[np.float64] | None = None
        self.path: NDArray[np.float64] | None = None
        self.frontiers: list[Frontier] = []  # the last call's frontiers (for drawing)
        self.goal_frontier: Frontier | None = None
        self.last_reason = ""  # why the last next_goal() returned None

    # -- bookkeeping ---------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget the blacklist, the virtual obstacles and the current goal."""
        self.blacklist.clear()
        self.virtual_obstacles.clear()
        self._abandoned.clear()
        self.goal_xy = None
        self.path = None
        self.goal_frontier = None

    def mark_failed(self, goal_xy: ArrayLike | None = None) -> None:
        """Blacklist ``goal_xy`` (default: the current goal): approach cells within
        ``blacklist_radius_m`` of it are never chosen again."""
        g = self.goal_xy if goal_xy is None else np.asarray(goal_xy, dtype=np.float64).reshape(2)
        if g is not None and np.isfinite(g).all():
            self.blacklist.append(np.array(g, dtype=np.float64))
        if goal_xy is None or (g is not None and self.goal_xy is not None and np.allclose(g, self.goal_xy)):
            self.goal_xy = None
            self.path = None
            self.goal_frontier = None

    def add_virtual_obstacle(self, points_xy: ArrayLike) -> None:
        """Treat the cells of ``(K, 2)`` map-frame points as occupied from now on (until :meth:`reset`)."""
        p = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
        p = p[np.isfinite(p).all(axis=1)]
        if len(p):
            self.virtual_obstacles.append(p)

    def mark_reached(self, goal_xy: ArrayLike | None = None) -> None:
        """The robot reached the goal: if its frontier is still there it cannot be cleared from this
        spot, so the spot is blacklisted like a failure."""
        self.mark_failed(goal_xy)

    # -- goal selection ------------------------------------------------------------------------
    def _costmap(self, grid: OccupancyGrid, robot_xy: NDArray[np.float64]) -> CostMap:
        return build_costmap(
            grid,
            self.robot_radius_m + self.inflation_padding_m,
            start_xy=robot_xy,
            occupied_threshold=self.occupied_threshold,
            unknown_is_obstacle=False,
            unknown_cost=self.unknown_cost,
            clearance_m=self.clearance_m,
            clearance_weight=self.clearance_weight,
            extra_obstacles_xy=np.concatenate(self.virtual_obstacles) if self.virtual_obstacles else None,
        )

    def next_goal(
        self, grid: OccupancyGrid, T_map_base: Pose2
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
        """``(goal_xy (2,), path (N, 2))`` towards the best reachable frontier, or None.

        ``last_reason`` tells why there is no goal: ``"no map"`` (non-finite pose, malformed grid, robot
        outside the grid or nothing observed yet: not a reason to stop exploring), ``"no frontier"`` or
        ``"no reachable frontier"`` (exploration done, as far as this map tells).
        """
        self.last_reason = ""
        robot = np.array([T_map_base.x, T_map_base.y], dtype=np.float64)
        data_all = np.asarray(grid.data)
        if not np.isfinite(robot).all() or data_all.ndim != 2 or not (data_all >= 0).any():
            self.last_reason = "no map"
            return None
        cm = self._costmap(grid, robot)
        data = np.asarray(grid.data)[cm.row0 : cm.row0 + cm.shape[0], cm.col0 : cm.col0 + cm.shape[1]]
        labels, n = label_frontiers(
            data, min_size_cells=self.min_frontier_size, free_threshold=self.free_threshold
        )
        self.frontiers = frontiers_from_labels(grid, labels, n, cm.row0, cm.col0)
        s_cell = cm.to_cells(robot[None])[0]
        if not cm.in_bounds(s_cell[None])[0]:
            self.last_reason = "no map"
            return None
        if n == 0:
            self.last_reason = "no frontier"
            self._note_abandoned(self.goal_xy)
            self._clear()
            return None
        start = (int(s_cell[0]), int(s_cell[1]))
        dist, pred = cost_to_go(cm, start)
        res = cm.resolution

        # nearest frontier cell of every cell: which frontier a candidate approach cell serves
        dist_f, (ir, ic) = ndimage.distance_transform_edt(labels == 0, return_indices=True)
        near_label = labels[ir, ic]
        usable = (
            cm.traversable
            & ~cm.unknown  # goals on observed cells only: the path may cross unknown, the goal may not
            & np.isfinite(dist)
            & (near_label > 0)
            & (cm.clearance >= self.robot_radius_m + self.goal_clearance_m)
        )
        sizes = np.array([f.size for f in self.frontiers], dtype=np.float64)
        prev = self.goal_xy

        # keep the current goal while it stays valid (hysteresis), unless a frontier is much cheaper
        keep: tuple[tuple[int, int], float, int] | None = None
        if prev is not None and not self._blacklisted(prev[None])[0]:
            g = cm.to_cells(prev[None])[0]
            gr, gc = int(g[0]), int(g[1])
            if (
                cm.in_bounds(g[None])[0]
                and usable[gr, gc]
                and dist_f[gr, gc] * res <= self.approach_radius_m + self.keep_slack_m
                and self._sees(cm, g[None, 0], g[None, 1], ir[gr, gc][None], ic[gr, gc][None])[0]
            ):
                glab = int(near_label[gr, gc])
                keep = ((gr, gc), dist[gr, gc] * res - self.gain_weight * sizes[glab - 1] * res, glab)
            elif np.linalg.norm(prev - robot) <= self.visit_radius_m:
                # its frontier vanished (or flickers) right next to the robot: call it visited
                self.blacklist.append(prev.copy())

        rows, cols = np.nonzero(usable & (dist_f * res <= self.approach_radius_m))
        ok = self._sees(cm, rows, cols, ir[rows, cols], ic[rows, cols])
        rows, cols = rows[ok], cols[ok]
        xy = cm.to_xy(np.stack([rows, cols], axis=1))
        ok = ~self._blacklisted(xy)
        rows, cols, xy = rows[ok], cols[ok], xy[ok]
        if rows.size == 0 and keep is None:
            self.last_reason = "no reachable frontier"
            self._note_abandoned(prev)
            self._clear()
            return None
        if rows.size:
            lab = near_label[rows, cols]
            path_cost = dist[rows, cols] * res
            score = path_cost - self.gain_weight * sizes[lab - 1] * res
            # best approach cell per frontier (cheapest to reach), then the best frontier
            order = np.lexsort((path_cost, lab))
            first = order[np.unique(lab[order], return_index=True)[1]]
            best = int(first[np.argmin(score[first])])
        if keep is not None and prev is not None and (rows.size == 0 or score[best] >= keep[1] - self.switch_margin_m):
            goal_cell, goal_label = keep[0], keep[2]
            goal_xy = prev.copy()
        else:
            goal_cell, goal_label = (int(rows[best]), int(cols[best])), int(lab[best])
            goal_xy = xy[best].copy()
            self._note_abandoned(prev)
        cells = extract_path(pred, cm.shape[1], goal_cell)
        local = smooth_path(cm, cells, cm.to_local(robot[None])[0], None)
        if len(local) == 1:
            local = np.vstack([cm.to_local(robot[None]), local])
        path = local_to_xy(cm, local)
        self.goal_xy = goal_xy
        self.path = path
        self.goal_frontier = self.frontiers[goal_label - 1]
        return self.goal_xy.copy(), path

    @staticmethod
    def _sees(
        cm: CostMap,
        rows: NDArray[np.int64],
        cols: NDArray[np.int64],
        fr: NDArray[np.int64],
        fc: NDArray[np.int64],
    ) -> NDArray[np.bool_]:
        """``(N,)`` True where the straight line from cell ``(rows, cols)`` to its frontier cell
        ``(fr, fc)`` crosses no occupied cell (an approach cell must see its frontier, not face it through
        a wall). Sampled every half cell at most (approach radii are a few cells)."""
        if len(rows) == 0:
            return np.zeros(0, dtype=bool)
        n = int(2 * max(1.0, float(np.max(np.hypot(fr - rows, fc - cols))))) + 2
        t = np.linspace(0.0, 1.0, n)[None, :]
        rr = np.rint(rows[:, None] + t * (fr - rows)[:, None]).astype(np.int64)
        cc = np.rint(cols[:, None] + t * (fc - cols)[:, None]).astype(np.int64)
        return np.asarray(~cm.occupied[rr, cc].any(axis=1), dtype=np.bool_)

    def _note_abandoned(self, goal: NDArray[np.float64] | None) -> None:
        """Count a goal given up for another one; a place abandoned ``max_abandons`` times (its frontier
        keeps appearing and vanishing) is blacklisted, which ends oscillations between goals."""
        if goal is None:
            return
        for entry in self._abandoned:
            if np.linalg.norm(entry[0] - goal) <= self.blacklist_radius_m:
                entry[1] += 1
                if entry[1] >= self.max_abandons:
                    self.blacklist.append(goal.copy())
                return
        self._abandoned.append([goal.copy(), 1])

    def _blacklisted(self, xy: NDArray[np.float64]) -> NDArray[np.bool_]:
        """``(N,)`` True for points within ``blacklist_radius_m`` of a blacklisted point."""
        if not self.blacklist or len(xy) == 0:
            return np.zeros(len(xy), dtype=bool)
        bl = np.asarray(self.blacklist)
        d2 = ((xy[:, None, :] - bl[None, :, :]) ** 2).sum(axis=2).min(axis=1)
        return d2 <= self.blacklist_radius_m**2

    def _clear(self) -> None:
        self.goal_xy = None
        self.path = None
        self.goal_frontier = None


class ExplorationController:
    """Exploration loop: goals from a :class:`FrontierExplorer`, motion from a :class:`PathFollower`.

    Call :meth:`compute` every control step with the latest SLAM grid, pose and scan; it returns the
    ``cmd_vel``. ``status``: ``"idle"`` (not started), ``"exploring"``, ``"done"`` (no reachable frontier
    left on ``done_confirmations`` consecutive new maps) or ``"stopped"``.
    """

    def __init__(
        self,
        robot: RobotConfig,
        *,
        explorer: FrontierExplorer | None = None,
        follower: PathFollower | None = None,
        replan_period_s: float = 1.0,
        progress_timeout_s: float = 15.0,
        progress_distance_m: float = 0.2,
        blocked_replan_s: float = 2.0,
        max_blocked_replans: int = 3,
        done_confirmations: int = 3,
        stuck_time_s: float = 3.0,
        stuck_distance_m: float = 0.05,
        stuck_min_cmd_mps: float = 0.05,
    ) -> None:
        self.robot = robot
        self.explorer = explorer or FrontierExplorer(robot.footprint_radius_m)
        self.follower = follower or PathFollower(robot, goal_tolerance_m=0.15)
        self.replan_period_s = float(replan_period_s)
        self.progress_timeout_s = float(progress_timeout_s)
        self.progress_distance_m = float(progress_distance_m)
        self.blocked_replan_s = float(blocked_replan_s)
        self.max_blocked_replans = int(max_blocked_replans)
        self.done_confirmations = int(done_confirmations)
        self.stuck = StuckDetector(
            time_s=stuck_time_s, distance_m=stuck_distance_m, min_cmd_mps=stuck_min_cmd_mps
        )
        self.stuck_events = 0
        self.status = "idle"
        self.goals_reached = 0
        self.goals_failed = 0
        self._reset_state()

    def _reset_state(self) -> None:
        self._last_plan_t = -math.inf
        self._last_map_key: tuple[int, float] | None = None
        self._none_count = 0
        self._checkpoint: NDArray[np.float64] | None = None
        self._checkpoint_t = 0.0
        self._blocked_since: float | None = None
        self._blocked_replans = 0
        self._stuck_now = False
        self.stuck.reset()

    @property
    def goal_xy(self) -> NDArray[np.float64] | None:
        return self.explorer.goal_xy

    @property
    def path(self) -> NDArray[np.float64] | None:
        return self.follower.path

    def start(self) -> None:
        """Start (or restart) exploring; the blacklist is kept across restarts of the same map."""
        self.status = "exploring"
        self._reset_state()
        self.follower.clear()
        self.explorer.goal_xy = None

    def stop(self) -> None:
        """Stop exploring (user takes over)."""
        self.status = "stopped"
        self.follower.clear()
        self.explorer.goal_xy = None

    def _fail_goal(self) -> None:
        self.explorer.mark_failed()
        self.goals_failed += 1
        self.follower.clear()
        self.stuck.reset()

    def compute(
        self,
        grid: OccupancyGrid,
        T_map_base: Pose2,
        scan: LaserScan | None = None,
        T_base_scan: Pose2 | None = None,
        now: float = 0.0,
    ) -> Twist:
        """One control step at sim time ``now`` (s). Returns the ``cmd_vel``."""
        if self.status != "exploring":
            return Twist()
        p = np.array([T_map_base.x, T_map_base.y])
        map_key = (id(grid), float(grid.stamp))
        new_map = map_key != self._last_map_key
        need_plan = self.follower.path is None and (
            new_map or now - self._last_plan_t >= self.replan_period_s
        )

        if self.follower.status == ARRIVED:
            self.explorer.mark_reached()
            self.goals_reached += 1
            self.follower.clear()
            need_plan = True
        elif self.follower.path is not None:
            # progress watchdog: the robot must move progress_distance_m every progress_timeout_s
            if self._checkpoint is None or np.linalg.norm(p - self._checkpoint) >= self.progress_distance_m:
                self._checkpoint, self._checkpoint_t = p, now
            elif now - self._checkpoint_t > self.progress_timeout_s:
                self._fail_goal()
                need_plan = True
            if self._stuck_now:
                # driven forward without moving: something the LIDAR does not see (glass) holds the robot
                self._stuck_now = False
                self.stuck_events += 1
                self.explorer.add_virtual_obstacle(
                    StuckDetector.obstacle_ahead(T_map_base, self.robot.footprint_radius_m)
                )
                self._fail_goal()
                need_plan = True
            if self.follower.status == BLOCKED:
                if self._blocked_since is None:
                    self._blocked_since = now
                elif now - self._blocked_since >= self.blocked_replan_s:
                    self._blocked_since = None
                    self._blocked_replans += 1
                    if self._blocked_replans > self.max_blocked_replans:
                        self._fail_goal()
                    need_plan = True
            else:
                self._blocked_since = None
            if new_map and now - self._last_plan_t >= self.replan_period_s:
                need_plan = True

        if need_plan:
            self._last_map_key = map_key
            self._last_plan_t = now
            old_goal = self.explorer.goal_xy
            try:
                result = self.explorer.next_goal(grid, T_map_base)
            except ValueError as e:  # a malformed grid: wait for the next one
                self.explorer.last_reason = f"no map ({e})"
                result = None
            if result is None:
                self.follower.clear()
                if not self.explorer.last_reason.startswith("no map"):
                    self._none_count += 1
                if self._none_count >= self.done_confirmations:
                    self.status = "done"
                return Twist()
            self._none_count = 0
            goal, path = result
            if old_goal is None or not np.allclose(goal, old_goal):
                self._checkpoint, self._checkpoint_t = p, now
                self._blocked_replans = 0
            self.follower.set_path(path)
        twist = self.follower.compute(T_map_base, scan, T_base_scan)
        self._stuck_now = self.stuck.update(now, T_map_base, twist)
        return twist
