"""Autonomy of the loop: route following, click-to-go (A* on the SLAM grid) and frontier exploration.

:class:`Autonomy` is a part of :class:`app.pipeline.Pipeline` (a mixin: it uses the pipeline's ``cfg``,
``world``, frames, ``last_scan`` and SLAM grid; its state, ``drive_mode``, ``nav_status`` and the
controllers, is set up in ``Pipeline.__init__``). The controllers are ``app.ocslam.navigation``'s.
"""

from __future__ import annotations

import numpy as np

from app.ocslam.messages import Twist

#: autonomy (route, go-to, exploration) control rate in sim time
CONTROL_HZ = 20.0


class Autonomy:
    """Who drives: teleop (which always takes over), a route, a go-to goal or the explorer."""

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
