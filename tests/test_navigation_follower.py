"""Path and route following in a kinematic (unicycle) simulation with synthetic scans."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.ocslam.config import RobotConfig
from app.ocslam.messages import LaserScan, Twist
from app.ocslam.navigation import PathFollower, RouteFollower
from app.ocslam.se2 import Pose2

ROBOT = RobotConfig()
DT = 0.05


def step(pose: Pose2, cmd: Twist, dt: float = DT) -> Pose2:
    """Exact unicycle motion over dt (arc), with the robot's limits."""
    v = float(np.clip(cmd.linear_x, -ROBOT.max_linear_mps, ROBOT.max_linear_mps))
    w = float(np.clip(cmd.angular_z, -ROBOT.max_angular_rps, ROBOT.max_angular_rps))
    if abs(w) < 1e-9:
        return pose @ Pose2(v * dt, 0.0, 0.0)
    r = v / w
    dth = w * dt
    return pose @ Pose2(r * math.sin(dth), r * (1 - math.cos(dth)), dth)


def scan_of_points(points_scan: np.ndarray, stamp: float = 0.0) -> LaserScan:
    """A 360-beam scan (1°) whose beams return the nearest of the given points (in base_scan) per beam."""
    ranges = np.full(360, np.inf)
    if len(points_scan):
        ang = np.arctan2(points_scan[:, 1], points_scan[:, 0])
        rng = np.hypot(points_scan[:, 0], points_scan[:, 1])
        idx = np.round((ang + math.pi) / math.radians(1.0)).astype(int) % 360
        for i, r in zip(idx, rng):
            ranges[i] = min(ranges[i], r)
    return LaserScan(stamp, -math.pi, math.radians(1.0), 0.12, 3.5, ranges)


def box_points_map(center: np.ndarray, half: float, spacing: float = 0.01) -> np.ndarray:
    """Outline of an axis-aligned square obstacle (map frame)."""
    s = np.arange(-half, half + 1e-9, spacing)
    c = np.asarray(center)
    return np.concatenate(
        [
            np.stack([c[0] + s, np.full_like(s, c[1] - half)], 1),
            np.stack([c[0] + s, np.full_like(s, c[1] + half)], 1),
            np.stack([np.full_like(s, c[0] - half), c[1] + s], 1),
            np.stack([np.full_like(s, c[0] + half), c[1] + s], 1),
        ]
    )


def run(follower, pose: Pose2, seconds: float, obstacles_map: np.ndarray | None = None, route: bool = False):
    """Drive until arrival/done or timeout; returns (poses, commands, statuses)."""
    poses, cmds, statuses = [pose], [], []
    T_base_scan = Pose2(-0.032, 0.0, 0.0)  # the Burger's LIDAR sits 3.2 cm behind the base centre
    t = 0.0
    while t < seconds:
        scan = None
        if obstacles_map is not None:
            T_map_scan = pose @ T_base_scan
            scan = scan_of_points(T_map_scan.inverse().transform_points(obstacles_map), t)
        if route:
            cmd = follower.compute(pose, scan, T_base_scan, now=t)
        else:
            cmd = follower.compute(pose, scan, T_base_scan)
        cmds.append(cmd)
        statuses.append(follower.status)
        if follower.status in ("arrived", "done"):
            break
        pose = step(pose, cmd)
        poses.append(pose)
        t += DT
    return poses, cmds, statuses


def test_converges_to_a_goal_within_tolerance_and_time() -> None:
    f = PathFollower(ROBOT, goal_tolerance_m=0.1)
    goal = np.array([2.0, 1.0])
    f.set_path(np.array([[0.0, 0.0], goal]))
    poses, cmds, statuses = run(f, Pose2(0.0, 0.0, 0.3), seconds=30.0)
    assert statuses[-1] == "arrived"
    end = poses[-1]
    assert math.hypot(end.x - goal[0], end.y - goal[1]) <= 0.1
    # straight-line distance 2.24 m at <= 0.22 m/s with a slow-down: well under 20 s
    assert len(cmds) * DT < 20.0
    assert all(abs(c.linear_x) <= 0.22 + 1e-9 and abs(c.angular_z) <= 1.5 + 1e-9 for c in cmds)
    assert all(c.linear_x >= 0 for c in cmds)
    # slows near the goal: the last commands are slower than cruising
    v = np.array([c.linear_x for c in cmds])
    assert v.max() == pytest.approx(0.22)
    assert v[-3:].max() < 0.1
    # arrived means stopped
    assert f.compute(end) == Twist()


def test_turns_in_place_when_the_goal_is_behind() -> None:
    f = PathFollower(ROBOT)
    f.set_path(np.array([[0.0, 0.0], [-1.5, 0.2]]))  # behind, slightly to the left
    poses, cmds, statuses = run(f, Pose2(0.0, 0.0, 0.0), seconds=30.0)
    first = cmds[:10]
    assert all(c.linear_x == 0.0 for c in first)
    assert all(c.angular_z > 0.0 for c in first)  # the short way round (left)
    # it only drives once roughly facing the path
    k = next(i for i, c in enumerate(cmds) if c.linear_x > 0)
    assert abs(math.remainder(poses[k].yaw - math.pi, 2 * math.pi)) < 0.9
    # and never drove backwards or away from the goal first
    xs = np.array([p.x for p in poses])
    assert xs.max() < 0.05
    assert statuses[-1] == "arrived"


def test_stops_for_an_obstacle_on_the_path() -> None:
    f = PathFollower(ROBOT, stop_distance_m=0.2)
    f.set_path(np.array([[0.0, 0.0], [3.0, 0.0]]))
    box = box_points_map(np.array([1.0, 0.0]), 0.1)  # a 20 cm box on the path, near face at x = 0.9
    poses, cmds, statuses = run(f, Pose2(0.0, 0.0, 0.0), seconds=20.0, obstacles_map=box)
    assert statuses[-1] == "blocked"
    assert cmds[-1] == Twist()
    stop_x = poses[-1].x
    # stopped before touching (front of the body at x + 0.105), not absurdly early
    assert stop_x + ROBOT.footprint_radius_m < 0.9
    assert stop_x > 0.9 - 0.105 - 0.2 - 0.2 - 0.1
    # it slowed down before stopping
    v = np.array([c.linear_x for c in cmds])
    assert v[-5:-1].max() < 0.22
    # obstacle gone: it resumes
    cmd = f.compute(poses[-1], scan_of_points(np.zeros((0, 2))), Pose2(-0.032, 0.0, 0.0))
    assert f.status == "following" and cmd.linear_x > 0


def test_obstacle_beside_the_path_does_not_block() -> None:
    f = PathFollower(ROBOT)
    f.set_path(np.array([[0.0, 0.0], [2.0, 0.0]]))
    wall = np.stack([np.linspace(-0.5, 2.5, 301), np.full(301, 0.25)], 1)  # a wall 25 cm to the left
    poses, cmds, statuses = run(f, Pose2(0.0, 0.0, 0.0), seconds=20.0, obstacles_map=wall)
    assert statuses[-1] == "arrived"
    assert "blocked" not in statuses


def test_turns_away_from_a_wall_ahead_when_the_path_turns() -> None:
    """Facing a wall 0.15 m ahead, with the path going left along it: the bumper box forbids driving
    into it, the robot turns in place towards the path and goes on."""
    f = PathFollower(ROBOT)
    f.set_path(np.array([[0.0, 0.0], [0.0, 1.5]]))
    wall = np.stack([np.full(301, 0.25), np.linspace(-1.0, 2.0, 301)], 1)
    poses, cmds, statuses = run(f, Pose2(0.0, 0.0, 0.0), seconds=20.0, obstacles_map=wall)
    assert statuses[-1] == "arrived"
    assert max(p.x for p in poses) < 0.25 - ROBOT.footprint_radius_m


def test_bad_paths_are_refused() -> None:
    f = PathFollower(ROBOT)
    with pytest.raises(ValueError):
        f.set_path(np.zeros((0, 2)))
    with pytest.raises(ValueError):
        f.set_path(np.array([[0.0, np.nan], [1.0, 1.0]]))
    assert f.compute(Pose2()) == Twist() and f.status == "idle"
    f.set_path([[1.0, 0.0]])  # a single point is a goal
    assert f.compute(Pose2()).linear_x > 0
    f.clear()
    assert f.compute(Pose2()) == Twist() and f.status == "idle"


def test_nan_ranges_are_skipped() -> None:
    f = PathFollower(ROBOT)
    f.set_path([[0.0, 0.0], [2.0, 0.0]])
    ranges = np.full(360, np.nan)
    scan = LaserScan(0.0, -math.pi, math.radians(1.0), 0.12, 3.5, ranges)
    cmd = f.compute(Pose2(), scan, Pose2())
    assert f.status == "following" and cmd.linear_x > 0


def square_route() -> np.ndarray:
    return np.array([[1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.0, 0.0]])


def test_route_follower_visits_waypoints_in_order() -> None:
    rf = RouteFollower(ROBOT, square_route(), waypoint_tolerance_m=0.2)
    poses, cmds, statuses = run(rf, Pose2(0.0, 0.0, 0.0), seconds=120.0, route=True)
    assert rf.done and statuses[-1] == "done" and rf.skipped == []
    xy = np.array([[p.x, p.y] for p in poses])
    # each waypoint was approached within the tolerance + the pure-pursuit corner cut, in order
    first_visit = []
    for w in square_route():
        d = np.linalg.norm(xy - w, axis=1)
        # the last waypoint is the start: look at the end of the run for it
        i = (
            int(np.argmax(d < 0.25))
            if not np.allclose(w, [0, 0])
            else len(xy) - 1 - int(np.argmax(d[::-1] < 0.25))
        )
        assert d[i] < 0.25
        first_visit.append(i)
    assert first_visit == sorted(first_visit)
    # the robot stayed near the polyline (cross-track error bounded by the lookahead's corner cutting)
    seg = np.vstack([[0.0, 0.0], square_route()])

    def dist_to_polyline(p):
        best = np.inf
        for a, b in zip(seg[:-1], seg[1:]):
            t = np.clip(np.dot(p - a, b - a) / np.dot(b - a, b - a), 0, 1)
            best = min(best, np.linalg.norm(p - (a + t * (b - a))))
        return best

    assert max(dist_to_polyline(p) for p in xy) < 0.15


def test_route_follower_skips_a_blocked_waypoint_after_the_timeout() -> None:
    route = np.array([[1.0, 0.0], [2.0, 0.0], [2.0, 1.0]])
    box = box_points_map(np.array([1.5, 0.0]), 0.1)  # blocks the leg to the second waypoint
    rf = RouteFollower(ROBOT, route, blocked_timeout_s=3.0)
    poses, cmds, statuses = run(rf, Pose2(0.0, 0.0, 0.0), seconds=120.0, obstacles_map=box, route=True)
    assert "blocked" in statuses
    assert rf.done and rf.skipped == [1]
    end = poses[-1]
    assert math.hypot(end.x - 2.0, end.y - 1.0) <= 0.1 + 1e-9
    # it never touched the box: centre-to-surface distance above the footprint radius
    xy = np.array([[p.x, p.y] for p in poses])
    assert np.linalg.norm(xy[:, None] - box[None], axis=2).min() > ROBOT.footprint_radius_m


def test_backs_off_when_blocked_too_close() -> None:
    """Blocked with a wall 12 cm ahead (inside the footprint radius + 4 cm): back off slowly, unless
    something is right behind too; with the wall 20 cm ahead just stop."""
    f = PathFollower(ROBOT)
    f.set_path([[0.0, 0.0], [2.0, 0.0]])

    def wall_at(x: float) -> np.ndarray:
        return np.stack([np.full(61, x), np.linspace(-0.3, 0.3, 61)], 1)

    cmd = f.compute(Pose2(), scan_of_points(wall_at(0.12)), Pose2())
    assert f.status == "blocked" and cmd.linear_x < 0 and cmd.angular_z == 0
    cmd = f.compute(Pose2(), scan_of_points(np.vstack([wall_at(0.12), wall_at(-0.13)])), Pose2())
    assert f.status == "blocked" and cmd == Twist()
    cmd = f.compute(Pose2(), scan_of_points(wall_at(0.2)), Pose2())
    assert f.status == "blocked" and cmd == Twist()
    f2 = PathFollower(ROBOT, back_off_mps=0.0)
    f2.set_path([[0.0, 0.0], [2.0, 0.0]])
    assert f2.compute(Pose2(), scan_of_points(wall_at(0.12)), Pose2()) == Twist()


@pytest.mark.parametrize("wobble", [0.0, 1e-9, -1e-9])
def test_an_out_and_back_route_turns_at_its_far_end_and_comes_home(wobble: float) -> None:
    """A corridor tour that goes 6 m out and back along the same line (a zoo world's kind): the way back passes under
    the robot all the way out, as near as the way out (an exact tie, or a nanometre either side); the robot never
    takes it for its progress, goes to the far end and comes home."""
    route = np.array([[0.0, 0.0], [6.0, 0.0], [0.0, 0.0]])
    rf = RouteFollower(ROBOT, route)
    poses, cmds, statuses = run(rf, Pose2(0.0, wobble, 0.0), seconds=120.0, route=True)
    assert rf.done and rf.skipped == []
    xy = np.array([[p.x, p.y] for p in poses])
    assert xy[:, 0].max() > 6.0 - rf.waypoint_tolerance_m - 0.05  # it went out to the far end
    assert math.hypot(*xy[-1]) <= 0.1 + 1e-9  # and came home
    assert len(poses) * DT < 2 * 6.0 / ROBOT.max_linear_mps + 15.0  # with no long stop on the way


def test_a_route_that_makes_no_progress_restarts_at_its_last_waypoint() -> None:
    """A robot that turns on the spot without getting anywhere (the pose given again and again, as in the simulator
    at an out-and-back route's far end) has its path restarted, once per ``stall_timeout_s``, at the last waypoint
    it visited; a robot that moves is left alone."""
    route = np.array([[0.0, 0.0], [6.0, 0.0], [0.0, 0.0]])
    rf = RouteFollower(ROBOT, route, stall_timeout_s=6.0)
    t = 0.0
    for x in np.arange(0.0, 5.85, 0.011):  # out along the corridor at 0.22 m/s
        rf.compute(Pose2(float(x), 0.0, 0.0), None, None, now=t)
        t += DT
    pose = Pose2(5.85, 0.0, 0.0)  # within the tolerance of the far waypoint, the way back under the robot
    t0 = t
    while t < t0 + 5.9:
        rf.compute(pose, None, None, now=t)
        t += DT
    assert rf.stalls == 0 and rf.current == 2
    while t < t0 + 6.5:
        rf.compute(pose, None, None, now=t)
        t += DT
    assert rf.stalls == 1
    np.testing.assert_allclose(rf.follower.path, route[1:])  # from the far waypoint, along the way back
    moving = RouteFollower(ROBOT, route, stall_timeout_s=6.0)
    poses, _, _ = run(moving, Pose2(0.0, 0.0, 0.0), seconds=20.0, route=True)
    assert moving.stalls == 0


CROSSING_LOOKS = np.array([[0.0, 0.0], [4.0, 0.0], [0.0, 0.0], [0.3, -0.55], [0.55, -0.16], [1.05, 0.18], [2.15, -0.45]])
#: corridor_offices' tour: a look that leaves from a waypoint and comes back 2 cm from it
RETURNING_LOOK = np.array([[5.68, 0.48], [5.88, 0.72], [5.82, 1.18], [5.62, 1.33], [4.23, 1.52], [4.35, 2.12],
                           [5.82, 1.18], [5.88, 0.72], [5.68, 0.48], [0.02, 0.03]])


@pytest.mark.parametrize(("route", "wobble"), [(CROSSING_LOOKS, 0.0), (CROSSING_LOOKS, 0.004), (CROSSING_LOOKS, -0.004),
                                               (RETURNING_LOOK, 0.0), (RETURNING_LOOK, 0.004)])
def test_a_route_whose_later_legs_pass_near_its_waypoints_visits_every_one(route: np.ndarray, wobble: float) -> None:
    """A tour planner's looks: legs that cross the way home, or come back a few centimetres from the waypoint they
    left from. Where a later leg passes that near, the robot is still on the leg it was following (within the
    follower's ``progress_tie_m``); pure pursuit a few centimetres off its leg must not jump to the later one and skip
    the waypoints in between (with a tie of 1 µm it skipped corridor_offices' look, 1.15 m away)."""
    rf = RouteFollower(ROBOT, route)
    poses, _, _ = run(rf, Pose2(route[0, 0], route[0, 1] + wobble, 0.0), seconds=120.0, route=True)
    assert rf.done and rf.skipped == []
    xy = np.array([[p.x, p.y] for p in poses])
    passed = np.hypot(xy[:, None, 0] - route[None, :, 0], xy[:, None, 1] - route[None, :, 1]).min(axis=0)
    assert (passed <= rf.waypoint_tolerance_m + 0.05).all(), passed
