"""Frontier detection and the frontier explorer's goal choice on hand-made grids."""

from __future__ import annotations

import numpy as np
import pytest

from app.ocslam.messages import OccupancyGrid
from app.ocslam.navigation import FrontierExplorer, find_frontiers
from app.ocslam.navigation.frontiers import frontier_mask
from app.ocslam.se2 import Pose2

RES = 0.05
R = 0.105


def grid_of(data: np.ndarray, origin: Pose2 = Pose2()) -> OccupancyGrid:
    return OccupancyGrid(RES, origin, np.asarray(data, dtype=np.int8))


def closed_room(h: int = 40, w: int = 60) -> np.ndarray:
    """Fully known room: free inside, walls all round, unknown beyond."""
    d = np.full((h + 10, w + 10), -1, dtype=np.int8)
    d[5 : 5 + h, 5 : 5 + w] = 0
    d[5, 5 : 5 + w] = d[4 + h, 5 : 5 + w] = 100
    d[5 : 5 + h, 5] = d[5 : 5 + h, 4 + w] = 100
    return d


def test_two_frontiers_count_size_and_centroids() -> None:
    """A known free strip (rows 10..19, cols 10..49) inside unknown, walled on top and bottom: the open
    left and right ends are two vertical frontiers of 10 cells each."""
    d = np.full((30, 60), -1, dtype=np.int8)
    d[10:20, 10:50] = 0
    d[9, 10:50] = d[20, 10:50] = 100
    fr = find_frontiers(grid_of(d))
    assert len(fr) == 2
    assert [f.size for f in fr] == [10, 10]
    cents = sorted(tuple(np.round(f.centroid_xy, 6)) for f in fr)
    y = 15.0 * RES  # mean of row centres 10.5 .. 19.5
    assert cents[0] == pytest.approx((10.5 * RES, y))
    assert cents[1] == pytest.approx((49.5 * RES, y))
    left = min(fr, key=lambda f: f.centroid_xy[0])
    assert (left.cells[:, 1] == 10).all() and sorted(left.cells[:, 0]) == list(range(10, 20))


def test_small_frontiers_are_dropped_and_diagonals_join() -> None:
    d = np.full((30, 30), 0, dtype=np.int8)
    d[0, :] = d[-1, :] = d[:, 0] = d[:, -1] = 100
    d[10, 10] = -1  # one unknown cell: its 4 free neighbours form a frontier of 4 cells (8-connected)
    g = grid_of(d)
    assert frontier_mask(d).sum() == 4
    assert find_frontiers(g, min_size_cells=5) == []
    (f,) = find_frontiers(g, min_size_cells=4)
    assert f.size == 4
    assert f.centroid_xy == pytest.approx([10.5 * RES, 10.5 * RES])


def test_grid_edge_counts_as_unknown_and_thresholds() -> None:
    d = np.zeros((10, 10), dtype=np.int8)
    fr = find_frontiers(grid_of(d))  # free cells on the border of the grid: one ring frontier
    assert len(fr) == 1 and fr[0].size == 36
    # cells seen once (occupancy 40) are frontier material by default, not with the map_server threshold
    d2 = np.full((20, 20), -1, dtype=np.int8)
    d2[5:15, 5:15] = 40
    assert len(find_frontiers(grid_of(d2))) == 1
    assert find_frontiers(grid_of(d2), free_threshold=25) == []


def test_rotated_origin_centroids() -> None:
    d = np.full((30, 60), -1, dtype=np.int8)
    d[10:20, 10:50] = 0
    d[9, 10:50] = d[20, 10:50] = 100
    origin = Pose2(1.0, 2.0, np.pi / 2)
    plain = sorted(tuple(f.centroid_xy) for f in find_frontiers(grid_of(d)))
    rot = sorted(tuple(f.centroid_xy) for f in find_frontiers(grid_of(d, origin)))
    expected = sorted(tuple(p) for p in origin.transform_points(np.array(plain)))
    assert np.allclose(rot, expected)


def test_closed_room_has_no_frontier_and_the_explorer_is_done() -> None:
    g = grid_of(closed_room())
    assert find_frontiers(g) == []
    ex = FrontierExplorer(R)
    assert ex.next_goal(g, Pose2(1.5, 1.0, 0.0)) is None


def two_openings() -> np.ndarray:
    """A known room (cols 10..69, rows 10..49) with two openings into unknown space: a near one in the west
    wall and a far one in the east wall."""
    d = np.full((60, 100), -1, dtype=np.int8)
    d[10:50, 10:70] = 0
    d[10, 10:70] = d[49, 10:70] = 100
    d[10:50, 10] = d[10:50, 69] = 100
    d[25:35, 10] = 0  # west opening: rows 25..34
    d[25:35, 69] = 0  # east opening
    return d


def test_explorer_picks_the_nearest_reachable_frontier() -> None:
    d = two_openings()
    g = grid_of(d)
    robot = Pose2(20 * RES, 30 * RES, 0.0)  # near the west opening
    ex = FrontierExplorer(R)
    goal, path = ex.next_goal(g, robot)
    assert goal[0] < 1.0  # the west frontier
    assert np.allclose(path[0], [robot.x, robot.y])
    assert np.allclose(path[-1], goal)
    # from near the east opening, the east frontier
    ex2 = FrontierExplorer(R)
    goal2, _ = ex2.next_goal(g, Pose2(60 * RES, 30 * RES, 0.0))
    assert goal2[0] > 3.0


def test_explorer_skips_unreachable_frontiers() -> None:
    """The nearer opening leads into a closed pocket of known free space with an unknown interior that
    the robot cannot enter (its door is 2 cells wide); the explorer must choose the far frontier."""
    d = two_openings()
    d[25:35, 0:10] = 0  # the west opening leads to a small known area ...
    d[24, 0:10] = d[35, 0:10] = 100
    d[25:35, 10] = 100
    d[29:31, 10] = 0  # ... through a 2-cell gap, closed by the inflation
    d[27:33, 2:5] = -1  # with an unknown blob inside: a frontier the robot cannot reach
    g = grid_of(d)
    ex = FrontierExplorer(R)
    goal, _ = ex.next_goal(g, Pose2(20 * RES, 30 * RES, 0.0))
    assert goal[0] > 3.0


def test_blacklist_and_hysteresis() -> None:
    d = two_openings()
    g = grid_of(d)
    robot = Pose2(30 * RES, 30 * RES, 0.0)  # nearer the west opening (1 m vs 2 m)
    ex = FrontierExplorer(R, switch_margin_m=1.5)
    west, _ = ex.next_goal(g, robot)
    assert west[0] < 1.0
    # hysteresis: from the middle the east frontier is now a bit cheaper, but not by the margin
    mid = Pose2(41 * RES, 30 * RES, 0.0)
    again, _ = ex.next_goal(g, mid)
    assert np.allclose(again, west)
    fresh, _ = FrontierExplorer(R).next_goal(g, mid)
    assert fresh[0] > 3.0
    # much nearer the east one: switch
    east, _ = ex.next_goal(g, Pose2(62 * RES, 30 * RES, 0.0))
    assert east[0] > 3.0
    # blacklisting the east goal sends the explorer west, whatever the distance
    ex.mark_failed()
    back, _ = ex.next_goal(g, Pose2(62 * RES, 30 * RES, 0.0))
    assert back[0] < 1.0
    ex.mark_failed(back)
    # both frontiers blacklisted near their approach cells: other approach cells of the 10-cell openings
    # lie within the 0.5 m blacklist radius too -> nothing left
    assert ex.next_goal(g, Pose2(40 * RES, 30 * RES, 0.0)) is None


def test_virtual_obstacle_closes_an_opening() -> None:
    d = two_openings()
    g = grid_of(d)
    ex = FrontierExplorer(R)
    # a virtual wall across the west opening (e.g. glass the robot got stuck on)
    ys = np.arange(24, 36) * RES + RES / 2
    ex.add_virtual_obstacle(np.stack([np.full_like(ys, 12.5 * RES), ys], axis=1))
    goal, _ = ex.next_goal(g, Pose2(20 * RES, 30 * RES, 0.0))
    assert goal[0] > 3.0
