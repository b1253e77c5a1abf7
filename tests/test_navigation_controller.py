"""The exploration controller's states: idle, exploring, done, stopped; stuck detection."""

from __future__ import annotations

import numpy as np

from app.ocslam.config import RobotConfig
from app.ocslam.messages import OccupancyGrid, Twist
from app.ocslam.navigation import ExplorationController
from app.ocslam.se2 import Pose2

RES = 0.05


def closed_room() -> OccupancyGrid:
    d = np.full((50, 70), -1, dtype=np.int8)
    d[5:45, 5:65] = 0
    d[5, 5:65] = d[44, 5:65] = 100
    d[5:45, 5] = d[5:45, 64] = 100
    return OccupancyGrid(RES, Pose2(), d)


def room_with_opening() -> OccupancyGrid:
    g = closed_room()
    g.data[20:30, 64] = 0  # an opening in the east wall onto unknown space
    return g


def test_idle_until_started_and_done_in_a_closed_room() -> None:
    ctl = ExplorationController(RobotConfig())
    g = closed_room()
    pose = Pose2(1.0, 1.0, 0.0)
    assert ctl.compute(g, pose, now=0.0) == Twist() and ctl.status == "idle"
    ctl.start()
    t = 0.0
    while ctl.status == "exploring" and t < 20.0:
        assert ctl.compute(g, pose, now=t) == Twist()
        t += 0.1
    assert ctl.status == "done"
    # three confirmations one replan period (1 s) apart, not on the first look
    assert 1.5 < t < 4.0


def test_drives_towards_the_frontier_and_stops_on_request() -> None:
    ctl = ExplorationController(RobotConfig())
    g = room_with_opening()
    ctl.start()
    pose = Pose2(1.0, 1.25, 0.0)  # facing the opening (east)
    cmd = ctl.compute(g, pose, now=0.0)
    assert ctl.status == "exploring"
    assert ctl.goal_xy is not None and ctl.goal_xy[0] > 2.7
    assert ctl.path is not None and np.allclose(ctl.path[0], [1.0, 1.25])
    assert cmd.linear_x > 0
    ctl.stop()
    assert ctl.status == "stopped" and ctl.compute(g, pose, now=0.1) == Twist()


def test_stuck_robot_marks_a_virtual_obstacle_and_gives_the_goal_up() -> None:
    """The robot is commanded forward but does not move (an invisible obstacle holds it)."""
    ctl = ExplorationController(RobotConfig())
    g = room_with_opening()
    ctl.start()
    pose = Pose2(1.0, 1.25, 0.0)
    first_goal = None
    t = 0.0
    while ctl.stuck_events == 0 and t < 10.0:
        ctl.compute(g, pose, now=t)
        if first_goal is None:
            first_goal = ctl.goal_xy.copy()
        t += 0.1
    assert ctl.stuck_events == 1
    assert 2.5 <= t <= 4.0  # stuck_time_s = 3 s
    assert ctl.goals_failed == 1 and ctl.explorer.blacklist
    (wall,) = ctl.explorer.virtual_obstacles
    # a short wall across the heading, just ahead of the robot's front
    assert np.allclose(wall[:, 0], 1.0 + 0.105 + 0.05)
    assert wall[:, 1].min() < 1.25 - 0.2 and wall[:, 1].max() > 1.25 + 0.2


def test_no_map_yet_is_not_done_and_bad_input_does_not_crash() -> None:
    ctl = ExplorationController(RobotConfig())
    ctl.start()
    placeholder = OccupancyGrid(
        RES, Pose2(), np.full((1, 1), -1, dtype=np.int8)
    )  # SLAM before its first scan
    empty = OccupancyGrid(RES, Pose2(), np.zeros((0, 0), dtype=np.int8))
    t = 0.0
    for g in (placeholder, empty):
        for _ in range(60):
            assert ctl.compute(g, Pose2(1.0, 1.0, 0.0), now=t) == Twist()
            t += 0.1
    assert ctl.status == "exploring" and ctl.explorer.last_reason.startswith("no map")
    assert ctl.compute(room_with_opening(), Pose2(float("nan"), 1.0, 0.0), now=t) == Twist()
    assert ctl.status == "exploring"
    # and then a real map: off it goes
    assert ctl.compute(room_with_opening(), Pose2(1.0, 1.25, 0.0), now=t + 1.0).linear_x > 0


def test_goto_controller_states() -> None:
    import pytest

    from app.ocslam.navigation import GoToController

    with pytest.raises(ValueError):
        GoToController(RobotConfig(), [float("nan"), 0.0])
    g = closed_room()
    goto = GoToController(RobotConfig(), [2.5, 1.25])
    cmd = goto.compute(g, Pose2(1.0, 1.25, 0.0), now=0.0)
    assert goto.status == "following" and cmd.linear_x > 0
    assert np.allclose(goto.path[-1], [2.5, 1.25])
    goto.cancel()
    assert goto.status == "cancelled" and goto.compute(g, Pose2(1.0, 1.25, 0.0), now=0.1) == Twist()
    # a goal outside the walls (known unknown beyond them) cannot be reached: failed at once
    out = GoToController(RobotConfig(), [3.4, 1.25])
    assert out.compute(g, Pose2(1.0, 1.25, 0.0), now=0.0) == Twist() and out.status == "failed"
    # already there
    here = GoToController(RobotConfig(), [1.02, 1.25])
    assert here.compute(g, Pose2(1.0, 1.25, 0.0), now=0.0) == Twist() and here.status == "arrived"
