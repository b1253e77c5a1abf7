"""Click-to-go: drive to one goal on the SLAM grid, replanning as the map changes.

:class:`GoToController` plans with :func:`~app.ocslam.navigation.astar.plan_path`, follows with a
:class:`~app.ocslam.navigation.follower.PathFollower` and replans when a new map arrives (at most every
``replan_period_s``) or when the follower has been blocked for ``blocked_replan_s``. A robot that is
driven but does not move gets a virtual obstacle ahead of it (:class:`StuckDetector`) before the replan.

``status``: ``"following"``, ``"arrived"``, ``"failed"`` (no path on the first try, or on
``max_plan_failures`` consecutive replans, or blocked on ``max_blocked_replans`` replans in a row) or
``"cancelled"``. Everything is in the ``map`` frame.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from app.ocslam.config import RobotConfig
from app.ocslam.messages import LaserScan, OccupancyGrid, Twist
from app.ocslam.navigation.astar import PlanOptions, plan_path
from app.ocslam.navigation.follower import ARRIVED, BLOCKED, PathFollower, StuckDetector
from app.ocslam.se2 import Pose2

if TYPE_CHECKING:
    from typing_extensions import Unpack  # typing.Unpack from Python 3.11


class GoToController:
    """Drive to ``goal_xy`` (``(2,)``, map frame) on the SLAM grid."""

    def __init__(
        self,
        robot: RobotConfig,
        goal_xy: ArrayLike,
        *,
        follower: PathFollower | None = None,
        replan_period_s: float = 2.0,
        blocked_replan_s: float = 2.0,
        max_blocked_replans: int = 5,
        max_plan_failures: int = 3,
        unknown_is_obstacle: bool = False,
        **plan_kwargs: Unpack[PlanOptions],
    ) -> None:
        goal = np.asarray(goal_xy, dtype=np.float64).reshape(2)
        if not np.isfinite(goal).all():
            raise ValueError(f"goal must be finite, got {goal}")
        self.robot = robot
        self.goal_xy = goal
        self.follower = follower or PathFollower(robot)
        self.replan_period_s = float(replan_period_s)
        self.blocked_replan_s = float(blocked_replan_s)
        self.max_blocked_replans = int(max_blocked_replans)
        self.max_plan_failures = int(max_plan_failures)
        self.unknown_is_obstacle = bool(unknown_is_obstacle)
        self.plan_kwargs = plan_kwargs
        self.status = "following"
        self.virtual_obstacles: list[NDArray[np.float64]] = []
        self.stuck = StuckDetector()
        self.replans = 0
        self._last_plan_t = -np.inf
        self._last_map_key: tuple[int, float] | None = None
        self._plan_failures = 0
        self._blocked_since: float | None = None
        self._blocked_replans = 0
        self._stuck_flag = False

    @property
    def path(self) -> NDArray[np.float64] | None:
        """The path being followed (``(N, 2)``, for drawing)."""
        return self.follower.path

    def cancel(self) -> None:
        """Stop (a new click or a teleop key)."""
        self.status = "cancelled"
        self.follower.clear()

    def _plan(self, grid: OccupancyGrid, T_map_base: Pose2) -> bool:
        extra = np.concatenate(self.virtual_obstacles) if self.virtual_obstacles else None
        path = plan_path(
            grid,
            (T_map_base.x, T_map_base.y),
            self.goal_xy,
            self.robot.footprint_radius_m,
            unknown_is_obstacle=self.unknown_is_obstacle,
            extra_obstacles_xy=extra,
            **self.plan_kwargs,
        )
        self.replans += 1
        if path is None:
            self._plan_failures += 1
            return False
        self._plan_failures = 0
        self.follower.set_path(path)
        return True

    def compute(
        self,
        grid: OccupancyGrid,
        T_map_base: Pose2,
        scan: LaserScan | None = None,
        T_base_scan: Pose2 | None = None,
        now: float = 0.0,
    ) -> Twist:
        """One control step at sim time ``now`` (s). Returns the ``cmd_vel``."""
        if self.status != "following":
            return Twist()
        map_key = (id(grid), float(grid.stamp))
        need = self.follower.path is None
        if self.follower.status == BLOCKED:
            if self._blocked_since is None:
                self._blocked_since = now
            elif now - self._blocked_since >= self.blocked_replan_s:
                self._blocked_since = None
                self._blocked_replans += 1
                need = True
        else:
            self._blocked_since = None
        if map_key != self._last_map_key and now - self._last_plan_t >= self.replan_period_s:
            need = True
        if self._stuck_flag:
            self._stuck_flag = False
            self.virtual_obstacles.append(
                StuckDetector.obstacle_ahead(T_map_base, self.robot.footprint_radius_m)
            )
            need = True
        if self._blocked_replans > self.max_blocked_replans:
            self.status = "failed"
            self.follower.clear()
            return Twist()
        if need and self.follower.status != ARRIVED:
            self._last_map_key = map_key
            self._last_plan_t = now
            try:
                ok = self._plan(grid, T_map_base)
            except ValueError:  # a malformed grid or pose: count it like a failed plan
                self._plan_failures += 1
                ok = False
            if not ok and (self.follower.path is None or self._plan_failures >= self.max_plan_failures):
                self.status = "failed"
                self.follower.clear()
                return Twist()
        twist = self.follower.compute(T_map_base, scan, T_base_scan)
        if self.follower.status == ARRIVED:
            self.status = "arrived"
            return Twist()
        if self.follower.status != BLOCKED:
            self._blocked_replans = 0  # count replans within one blocked episode only
        self._stuck_flag = self.stuck.update(now, T_map_base, twist)
        return twist
