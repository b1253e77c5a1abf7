"""Path following: pure pursuit with rotate-in-place, goal slow-down and a LIDAR safety stop.

:class:`PathFollower` tracks an ``(N, 2)`` polyline in the ``map`` frame and turns the robot pose
``T_map_base`` (and the latest LIDAR scan) into a :class:`~app.ocslam.messages.Twist` (``cmd_vel``).
:class:`RouteFollower` visits a list of waypoints in order with the same controller.

Safety stop (the scan's valid returns, mapped through ``T_base_scan`` and ``T_map_base``):

* *path check*: the robot's centre, moved along the path over the next ``stop_distance_m``, must not
  come closer to a scan point than both ``path_check_radius_m`` and its current clearance
  (:func:`first_conflict`). If it would, the status is ``"blocked"`` and the twist zero (until the
  obstacle leaves or the caller replans); within a further
  ``obstacle_slowdown_m`` the speed is reduced. This catches obstacles *on* the path that the map does
  not hold yet; clearance from mapped obstacles is the planner's job (its inflation is measured between
  cell centres, so LIDAR returns on an obstacle's surface may lie up to about half a cell closer than
  the robot's radius: the check radius defaults to ``0.75 × radius`` so that valid paths through tight
  gaps are not refused). A robot already that close to something (squeezed next to a wall) may move
  as long as it gets no closer.
* *arc check*: the same test with the full footprint radius along the arc pure pursuit is about to
  drive (it cuts corners); if that arc is not clear the robot turns in place towards the path first.
* *bumper box*: a point right in front of the body (``0 < x <= radius + emergency_distance``,
  ``|y| <= bumper_half_width``, default ``0.85 × radius``, about the Burger's real half-width) forbids
  driving forward (pure pursuit cuts corners a little); the robot turns in place towards the path if
  that direction is free, else reports ``"blocked"``.

While blocked the twist is zero, except when something in front is closer than ``radius +
back_off_margin_m`` and the space behind is free: then the robot backs off slowly (``back_off_mps``,
0 disables it), so that the caller's next plan starts from outside the obstacle's inflation.

Rotating in place is always allowed: the TurtleBot3 Burger is round.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from app.ocslam.config import RobotConfig
from app.ocslam.messages import LaserScan, Twist
from app.ocslam.se2 import Pose2

IDLE, FOLLOWING, ARRIVED, BLOCKED, DONE = "idle", "following", "arrived", "blocked", "done"


def _as_path(path_xy: ArrayLike) -> NDArray[np.float64]:
    p = np.asarray(path_xy, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or len(p) == 0:
        raise ValueError(f"path must be an (N, 2) array with N >= 1, got shape {p.shape}")
    if not np.isfinite(p).all():
        raise ValueError("path contains non-finite coordinates")
    return p


def scan_points_base(scan: LaserScan | None, T_base_scan: Pose2) -> NDArray[np.float64]:
    """``(M, 2)`` valid scan returns in ``base_footprint`` (NaN/inf/out-of-range beams are skipped)."""
    if scan is None or len(scan.ranges) == 0:
        return np.zeros((0, 2))
    return T_base_scan.transform_points(scan.points())


def corridor_clearance(points_base: NDArray[np.float64], heading: float, half_width: float) -> float:
    """Distance along ``heading`` (rad, in ``base_footprint``) to the nearest point of ``points_base``
    inside the corridor ``|lateral| <= half_width`` ahead of the robot; ``inf`` if none."""
    if len(points_base) == 0:
        return math.inf
    c, s = math.cos(heading), math.sin(heading)
    along = c * points_base[:, 0] + s * points_base[:, 1]
    lateral = -s * points_base[:, 0] + c * points_base[:, 1]
    m = (along > 0.0) & (np.abs(lateral) <= half_width)
    return float(along[m].min()) if m.any() else math.inf


def first_conflict(
    points: NDArray[np.float64], samples: NDArray[np.float64], p_now: NDArray[np.float64], radius: float
) -> int:
    """Index of the first of ``samples`` (``(K, 2)`` future robot positions) where the robot would be
    closer to one of ``points`` (``(M, 2)`` obstacle points, same frame) than ``radius`` *and* than its
    current clearance ``min |points − p_now|`` minus 1 cm; ``-1`` if none.

    The second condition lets a robot that is already closer than ``radius`` to something (squeezed
    along a wall, leaving a tight spot) move as long as it does not get any closer, while an obstacle
    on its way still stops it.
    """
    if len(points) == 0 or len(samples) == 0:
        return -1
    d_now = np.linalg.norm(points - p_now, axis=1)
    reach = float(np.max(np.linalg.norm(samples - p_now, axis=1))) + radius + 0.05
    near = d_now <= reach
    if not near.any():
        return -1
    limit = min(radius, float(d_now.min()) - 0.01)
    pts = points[near]
    d = np.linalg.norm(pts[:, None, :] - samples[None, :, :], axis=2).min(axis=0)
    bad = d < limit
    return int(np.argmax(bad)) if bad.any() else -1


class PathFollower:
    """Pure-pursuit follower of a polyline in the ``map`` frame.

    ``status`` is ``"idle"`` (no path), ``"following"``, ``"arrived"`` (within ``goal_tolerance_m`` of
    the last point; the twist is zero until a new path is set) or ``"blocked"`` (an obstacle in the stop
    box and no clear way to turn towards the path).
    """

    _ALIGNED_RAD = 0.05  # below this heading error, a blocked stop box means "blocked", not "turn"

    def __init__(
        self,
        robot: RobotConfig,
        *,
        lookahead_m: float = 0.3,
        goal_tolerance_m: float = 0.1,
        max_linear_mps: float = 0.22,
        max_angular_rps: float = 1.5,
        stop_distance_m: float = 0.2,
        path_check_radius_m: float | None = None,
        bumper_half_width_m: float | None = None,
        arc_check_radius_m: float | None = None,
        rotate_in_place_rad: float = 0.9,
        rotate_done_rad: float = 0.3,
        slowdown_distance_m: float = 0.5,
        obstacle_slowdown_m: float = 0.3,
        emergency_distance_m: float = 0.05,
        back_off_mps: float = 0.05,
        back_off_margin_m: float = 0.04,
        min_linear_mps: float = 0.03,
        min_angular_rps: float = 0.3,
        heading_gain: float = 2.5,
        progress_tie_m: float = 0.1,
    ) -> None:
        if lookahead_m <= 0 or goal_tolerance_m <= 0:
            raise ValueError("lookahead_m and goal_tolerance_m must be > 0")
        self.robot = robot
        self.radius = float(robot.footprint_radius_m)
        self.lookahead_m = float(lookahead_m)
        self.goal_tolerance_m = float(goal_tolerance_m)
        self.max_linear_mps = float(min(max_linear_mps, robot.max_linear_mps))
        self.max_angular_rps = float(min(max_angular_rps, robot.max_angular_rps))
        self.stop_distance_m = float(stop_distance_m)
        self.path_check_radius_m = float(
            path_check_radius_m if path_check_radius_m is not None else 0.75 * self.radius
        )
        self.arc_check_radius_m = float(arc_check_radius_m if arc_check_radius_m is not None else self.radius)
        self.bumper_half_width_m = float(
            bumper_half_width_m if bumper_half_width_m is not None else 0.85 * self.radius
        )
        self.rotate_in_place_rad = float(rotate_in_place_rad)
        self.rotate_done_rad = float(min(rotate_done_rad, rotate_in_place_rad))
        self.slowdown_distance_m = float(slowdown_distance_m)
        self.obstacle_slowdown_m = float(obstacle_slowdown_m)
        self.emergency_distance_m = float(emergency_distance_m)
        self.back_off_mps = float(max(0.0, back_off_mps))
        self.back_off_margin_m = float(back_off_margin_m)
        self.min_linear_mps = float(min(min_linear_mps, self.max_linear_mps))
        self.min_angular_rps = float(min(min_angular_rps, self.max_angular_rps))
        self.heading_gain = float(heading_gain)
        self.progress_tie_m = float(max(0.0, progress_tie_m))
        self.path: NDArray[np.float64] | None = None
        self.status: str = IDLE
        self.progress_index = 0
        self.target_xy: NDArray[np.float64] | None = None  # last lookahead point (for drawing)
        self.path_clearance_m = math.inf  # free path length ahead at the last step (m)
        self._rotating = False
        self._cum = np.zeros(1)
        self._last_s = 0.0

    # -- path ------------------------------------------------------------------------------------
    def set_path(self, path_xy: ArrayLike) -> None:
        """Follow ``(N, 2)`` waypoints in the ``map`` frame (N >= 1; one point means "go there")."""
        p = _as_path(path_xy)
        if len(p) == 1:
            p = np.vstack([p, p])
        self.path = p
        seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
        self._cum = np.concatenate([[0.0], np.cumsum(seg)])
        self.progress_index = 0
        self._last_s = 0.0
        self.status = FOLLOWING
        self._rotating = False
        self.target_xy = None

    def clear(self) -> None:
        """Drop the path; the follower idles (zero twist)."""
        self.path = None
        self.status = IDLE
        self.progress_index = 0
        self._rotating = False
        self.target_xy = None

    @property
    def goal_xy(self) -> NDArray[np.float64] | None:
        return None if self.path is None else self.path[-1]

    def _project(self, p: NDArray[np.float64]) -> tuple[int, float, float]:
        """Project ``p`` on the path segments from ``progress_index`` up to a short window ahead.

        Returns ``(segment, arclength, distance)`` and never moves backwards along the path.
        """
        assert self.path is not None
        a, b = self.path[:-1], self.path[1:]
        n = len(a)
        k0 = min(self.progress_index, n - 1)
        window_end = self._cum[k0 + 1] + self.lookahead_m + 1.0
        k1 = int(np.searchsorted(self._cum[:-1], window_end, side="right"))
        k1 = max(k0 + 1, min(n, k1))
        aa, bb = a[k0:k1], b[k0:k1]
        d = bb - aa
        L2 = (d * d).sum(axis=1)
        t = np.where(L2 > 0, ((p - aa) * d).sum(axis=1) / np.where(L2 > 0, L2, 1.0), 0.0)
        t = np.clip(t, 0.0, 1.0)
        q = aa + t[:, None] * d
        dist = np.linalg.norm(q - p, axis=1)
        s_all = self._cum[k0:k1] + t * np.sqrt(L2)
        # where segments are about as near (within ``progress_tie_m``: a path that retraces or crosses itself — the way
        # back of an out-and-back route passes under the robot on its way out, a look's way back passes a few
        # centimetres from the waypoint the look left from), the robot is on the one nearest its last progress: a
        # pursuit a few centimetres off its leg must not jump to a later leg and skip the waypoints between
        tied = np.flatnonzero(dist <= dist.min() + self.progress_tie_m + 1e-9)
        i = int(tied[np.argmin(np.abs(s_all[tied] - self._last_s))])
        k = k0 + i
        return k, float(s_all[i]), float(dist[i])

    def _point_at(self, s: float) -> NDArray[np.float64]:
        assert self.path is not None
        s = min(max(s, 0.0), float(self._cum[-1]))
        return np.array([np.interp(s, self._cum, self.path[:, 0]), np.interp(s, self._cum, self.path[:, 1])])

    def _path_clearance(self, p: NDArray[np.float64], s: float, pts_map: NDArray[np.float64]) -> float:
        """Arc length from the robot's projection ``s`` to the first path sample (every 5 cm up to
        ``stop_distance + obstacle_slowdown``) where a disk of ``path_check_radius_m`` would conflict with
        a scan point (``(M, 2)``, map frame; see :func:`first_conflict`); ``inf`` if none."""
        horizon = self.stop_distance_m + self.obstacle_slowdown_m
        ds = np.arange(0.0, horizon + 1e-9, 0.05)
        assert self.path is not None
        sa = np.minimum(s + ds, self._cum[-1])
        samples = np.stack(
            [np.interp(sa, self._cum, self.path[:, 0]), np.interp(sa, self._cum, self.path[:, 1])], 1
        )
        k = first_conflict(pts_map, samples, p, self.path_check_radius_m)
        return float(ds[k]) if k >= 0 else math.inf

    @property
    def remaining_m(self) -> float:
        """Path length left from the last projection (0 without a path)."""
        if self.path is None:
            return 0.0
        return float(self._cum[-1] - self._last_s)

    # -- control ---------------------------------------------------------------------------------
    def compute(
        self, T_map_base: Pose2, scan: LaserScan | None = None, T_base_scan: Pose2 | None = None
    ) -> Twist:
        """One control step: the ``cmd_vel`` for the robot at ``T_map_base`` given the latest scan."""
        if self.path is None:
            self.status = IDLE
            return Twist()
        if self.status == ARRIVED:
            return Twist()
        p = np.array([T_map_base.x, T_map_base.y])
        if not np.isfinite(p).all() or not math.isfinite(T_map_base.yaw):
            self.status = BLOCKED
            return Twist()
        k, s, _ = self._project(p)
        self.progress_index = k
        self._last_s = s
        goal = self.path[-1]
        d_goal = float(np.linalg.norm(goal - p))
        total = float(self._cum[-1])
        remaining = total - s
        last_seg = k >= len(self.path) - 2
        if d_goal <= self.goal_tolerance_m and (last_seg or remaining <= self.lookahead_m):
            self.status = ARRIVED
            self._rotating = False
            return Twist()

        target = goal if s + self.lookahead_m >= total else self._point_at(s + self.lookahead_m)
        self.target_xy = target
        t_base = T_map_base.inverse().transform_points(target[None])[0]
        ld = float(math.hypot(t_base[0], t_base[1]))
        alpha = math.atan2(t_base[1], t_base[0]) if ld > 1e-9 else 0.0

        if self._rotating and abs(alpha) < self.rotate_done_rad:
            self._rotating = False
        elif not self._rotating and abs(alpha) > self.rotate_in_place_rad:
            self._rotating = True

        pts = scan_points_base(scan, T_base_scan if T_base_scan is not None else Pose2())
        along = self._path_clearance(p, s, T_map_base.transform_points(pts) if len(pts) else pts)
        self.path_clearance_m = along
        if along <= self.stop_distance_m:
            self.status = BLOCKED
            return self._back_off(pts)
        bumper = self.radius + self.emergency_distance_m
        half = self.bumper_half_width_m
        if not self._rotating and corridor_clearance(pts, 0.0, half) <= bumper:
            # something right in front of the body: turn towards the path if that way is free
            if abs(alpha) > self._ALIGNED_RAD and corridor_clearance(pts, alpha, half) > bumper:
                self._rotating = True
            else:
                self.status = BLOCKED
                return self._back_off(pts)
        self.status = FOLLOWING

        if self._rotating:
            w = self.heading_gain * alpha
            w = math.copysign(min(max(abs(w), self.min_angular_rps), self.max_angular_rps), alpha)
            return Twist(0.0, w)

        # pure pursuit: curvature of the arc through the lookahead point
        kappa = 2.0 * t_base[1] / (ld * ld) if ld > 1e-9 else 0.0
        v = self.max_linear_mps
        dist_left = min(d_goal, remaining + d_goal)
        v = min(v, max(self.min_linear_mps, self.max_linear_mps * dist_left / self.slowdown_distance_m))
        if math.isfinite(along):
            room = (along - self.stop_distance_m) / self.obstacle_slowdown_m
            v = min(v, max(self.min_linear_mps, self.max_linear_mps * min(1.0, room)))
        if abs(kappa) * v > self.max_angular_rps:
            v = max(self.max_angular_rps / abs(kappa), 0.0)
        if not self._arc_clear(pts, kappa):
            # the arc we are about to drive (pure pursuit cuts corners) grazes an obstacle the path
            # avoids: turn in place towards the path first
            if abs(alpha) > self._ALIGNED_RAD:
                self._rotating = True
                w = self.heading_gain * alpha
                return Twist(
                    0.0, math.copysign(min(max(abs(w), self.min_angular_rps), self.max_angular_rps), alpha)
                )
            self.status = BLOCKED
            return self._back_off(pts)
        w = float(np.clip(v * kappa, -self.max_angular_rps, self.max_angular_rps))
        return Twist(float(v), w)

    def _back_off(self, pts_base: NDArray[np.float64]) -> Twist:
        """The twist while blocked: zero, or a slow reverse when something in front is closer than
        ``radius + back_off_margin_m`` and the space behind the robot is free (a recovery for a robot
        that ended up too close to an obstacle: from a little farther the next plan can go round it)."""
        if self.back_off_mps <= 0 or len(pts_base) == 0:
            return Twist()
        d = np.hypot(pts_base[:, 0], pts_base[:, 1])
        i = int(np.argmin(d))
        if d[i] >= self.radius + self.back_off_margin_m or pts_base[i, 0] <= 0.0:
            return Twist()
        rear = corridor_clearance(pts_base, math.pi, self.bumper_half_width_m)
        if rear <= self.radius + self.emergency_distance_m:
            return Twist()
        return Twist(-self.back_off_mps, 0.0)

    def _arc_clear(self, pts_base: NDArray[np.float64], kappa: float) -> bool:
        """True unless the body (``arc_check_radius_m``, default the footprint radius) on the circular arc
        of curvature ``kappa`` ahead (``stop_distance_m`` long) conflicts with a scan point (``(M, 2)``,
        base frame; see :func:`first_conflict`)."""
        s = np.arange(0.05, self.stop_distance_m + 1e-9, 0.05)
        if abs(kappa) < 1e-6:
            arc = np.stack([s, np.zeros_like(s)], 1)
        else:
            arc = np.stack([np.sin(kappa * s) / kappa, (1.0 - np.cos(kappa * s)) / kappa], 1)
        return first_conflict(pts_base, arc, np.zeros(2), self.arc_check_radius_m) < 0


class RouteFollower:
    """Visit ``(N, 2)`` waypoints (``map`` frame) in order with a :class:`PathFollower`.

    The robot follows the polyline ``[start, w_k, …, w_N-1]`` from the next unvisited waypoint ``w_k``.
    A waypoint counts as visited when the robot comes within ``waypoint_tolerance_m`` of it or its
    progress along the polyline passes it. After ``stall_timeout_s`` of following without progress the path
    starts again at the last waypoint visited (:meth:`_recover_from_stall`). If the follower stays blocked for
    ``blocked_timeout_s`` the current waypoint is skipped (recorded in ``skipped``). ``done`` once the last one is reached or
    skipped; ``status`` mirrors the follower's, with ``"done"`` at the end.

    With no planner behind it to keep clearance from mapped obstacles, the follower's path check uses
    the full footprint radius plus 2 cm by default (``path_check_radius_m``).
    """

    def __init__(
        self,
        robot: RobotConfig,
        waypoints_xy: ArrayLike,
        *,
        waypoint_tolerance_m: float = 0.25,
        blocked_timeout_s: float = 10.0,
        stall_timeout_s: float = 6.0,
        **follower_kwargs: float,
    ) -> None:
        self.waypoints = _as_path(waypoints_xy)
        follower_kwargs.setdefault("path_check_radius_m", robot.footprint_radius_m + 0.02)
        self.follower = PathFollower(robot, **follower_kwargs)
        self.waypoint_tolerance_m = float(waypoint_tolerance_m)
        self.blocked_timeout_s = float(blocked_timeout_s)
        self.stall_timeout_s = float(stall_timeout_s)
        self.stalls = 0  # restarts after following without progress (:meth:`_recover_from_stall`)
        self._progress_mark: tuple[int, float] | None = None
        self._progress_since = 0.0
        self.current = 0
        self.skipped: list[int] = []
        self.done = False
        self.status = IDLE
        self._k0 = 0
        self._blocked_since: float | None = None

    def _recover_from_stall(self, p: NDArray[np.float64], now: float) -> None:
        """Restart the path at the last waypoint visited, along the route's own legs (from the robot before the
        first), after ``stall_timeout_s`` of following without progress (neither a new waypoint nor 5 cm along the
        path): where a route turns back on itself along the same line (out and back along a corridor), the pursuit
        point a lookahead along the path lies on the way back, under the robot, which spins there."""
        mark = (self.current, -self.follower.remaining_m)
        last = self._progress_mark
        if last is None or mark[0] != last[0] or abs(mark[1] - last[1]) > 0.05 or self.follower.status != FOLLOWING:
            self._progress_mark, self._progress_since = mark, now
        elif now - self._progress_since >= self.stall_timeout_s:
            self.stalls += 1
            self._restart(p, from_last_visited=True)
            self._progress_mark, self._progress_since = None, now

    def _restart(self, p: NDArray[np.float64], from_last_visited: bool = False) -> None:
        """Follow the waypoints left from the robot at ``p``, or (``from_last_visited``, once one was) from the last
        waypoint visited, along the route's own legs."""
        self._k0 = self.current
        if from_last_visited and self.current > 0:
            self.follower.set_path(self.waypoints[self.current - 1 :])
        else:
            self.follower.set_path(np.vstack([p[None], self.waypoints[self.current :]]))

    def compute(
        self,
        T_map_base: Pose2,
        scan: LaserScan | None = None,
        T_base_scan: Pose2 | None = None,
        now: float | None = None,
    ) -> Twist:
        """One control step. ``now`` (s, sim time; default the scan's stamp) times the blocked timeout."""
        if self.done:
            self.status = DONE
            return Twist()
        if now is None:
            now = scan.stamp if scan is not None else 0.0
        p = np.array([T_map_base.x, T_map_base.y])
        if self.follower.path is None:
            self._restart(p)
        n = len(self.waypoints)
        while (
            self.current < n - 1
            and np.linalg.norm(self.waypoints[self.current] - p) <= self.waypoint_tolerance_m
        ):
            self.current += 1
        self._recover_from_stall(p, now)
        twist = self.follower.compute(T_map_base, scan, T_base_scan)
        self.current = max(self.current, min(n - 1, self._k0 + self.follower.progress_index))
        if self.follower.status == ARRIVED:
            self.current = n
            self.done = True
            self.status = DONE
            return Twist()
        if self.follower.status == BLOCKED:
            if self._blocked_since is None:
                self._blocked_since = now
            elif now - self._blocked_since >= self.blocked_timeout_s:
                self._blocked_since = None
                self.skipped.append(self.current)
                self.current += 1
                if self.current >= n:
                    self.done = True
                    self.status = DONE
                    return Twist()
                self._restart(p)
                twist = Twist()
        else:
            self._blocked_since = None
        self.status = self.follower.status
        return twist


class StuckDetector:
    """Notices a robot that is driven forward but does not move: something its LIDAR does not see (glass,
    a low obstacle, a caster caught on a rug) holds it.

    Feed every control step with :meth:`update`; it returns True once the commanded forward speed has
    averaged at least ``min_cmd_mps`` over the last ``time_s`` while the robot stayed within
    ``distance_m`` of where it was. :meth:`obstacle_ahead` gives the points of a short virtual wall
    across the heading, just ahead of the robot's front, to keep the planner away from that spot.
    """

    def __init__(self, *, time_s: float = 3.0, distance_m: float = 0.05, min_cmd_mps: float = 0.05) -> None:
        self.time_s = float(time_s)
        self.distance_m = float(distance_m)
        self.min_cmd_mps = float(min_cmd_mps)
        self._history: list[tuple[float, float, float, float]] = []  # (t, x, y, commanded v)

    def reset(self) -> None:
        self._history.clear()

    def update(self, now: float, T_map_base: Pose2, cmd: Twist) -> bool:
        """Record one step (sim time ``now``, pose, the twist just commanded); True when stuck."""
        h = self._history
        h.append((float(now), float(T_map_base.x), float(T_map_base.y), float(cmd.linear_x)))
        while h and now - h[0][0] > self.time_s:
            h.pop(0)
        if now - h[0][0] < 0.9 * self.time_s:
            return False
        v = sum(e[3] for e in h) / len(h)
        moved = max(math.hypot(e[1] - T_map_base.x, e[2] - T_map_base.y) for e in h)
        if v >= self.min_cmd_mps and moved < self.distance_m:
            h.clear()
            return True
        return False

    @staticmethod
    def obstacle_ahead(T_map_base: Pose2, radius_m: float, spacing_m: float = 0.025) -> NDArray[np.float64]:
        """``(K, 2)`` map-frame points of a wall piece ``4·radius`` wide, ``radius + 5 cm`` ahead."""
        lateral = np.arange(-2.0 * radius_m, 2.0 * radius_m + spacing_m / 2, spacing_m)
        ahead = np.full_like(lateral, radius_m + 0.05)
        return T_map_base.transform_points(np.stack([ahead, lateral], axis=1))
