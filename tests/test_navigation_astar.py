"""A* planning: known shortest paths, unreachable goals, snapping, escaping, and properties on random grids."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from app.ocslam.messages import OccupancyGrid
from app.ocslam.navigation import astar, build_costmap, cost_to_go, inflate, plan_path
from app.ocslam.se2 import Pose2

RES = 0.05
R = 0.105
PAD = 0.025  # plan_path's default inflation padding
RP = R + PAD


def grid_of(data: np.ndarray, origin: Pose2 = Pose2()) -> OccupancyGrid:
    return OccupancyGrid(RES, origin, np.asarray(data, dtype=np.int8))


def length(path: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())


def cell_xy(r: float, c: float) -> np.ndarray:
    return np.array([(c + 0.5) * RES, (r + 0.5) * RES])


def test_straight_path_in_an_empty_grid() -> None:
    g = grid_of(np.zeros((60, 100)))
    start, goal = cell_xy(30, 10), cell_xy(30, 90)
    path = plan_path(g, start, goal, R)
    assert path is not None
    assert len(path) == 2  # smoothing leaves one straight segment
    assert np.allclose(path[0], start) and np.allclose(path[-1], goal)
    assert length(path) == pytest.approx(80 * RES)
    # a diagonal goal: still one segment, whatever the grid staircase
    path = plan_path(g, cell_xy(5, 5), cell_xy(50, 80), R)
    assert len(path) == 2


def upper_hull_length(points: np.ndarray) -> float:
    """Length of the upper convex hull chain of ``(N, 2)`` points from the leftmost to the rightmost."""
    pts = sorted(map(tuple, points))
    hull: list[tuple[float, float]] = []
    for p in pts:
        while len(hull) >= 2:
            (x1, y1), (x2, y2) = hull[-2], hull[-1]
            if (x2 - x1) * (p[1] - y1) - (y2 - y1) * (p[0] - x1) >= 0:  # not a right turn: drop
                hull.pop()
            else:
                break
        hull.append(p)
    return float(np.linalg.norm(np.diff(np.array(hull), axis=0), axis=1).sum())


def test_path_around_a_wall_is_near_the_shortest() -> None:
    """A wall from the bottom edge up to y = 2 m, start and goal 1 m on either side at y = 0.5 m.

    The robot's centre may not enter the inflated cells (squares; radius + the default padding), which
    form one obstacle standing on the bottom edge, so the shortest path from start to goal is the upper
    convex hull of the start, the goal and the corners of the blocked squares. With clearance_weight=0 the planner must be within 2 %.
    """
    d = np.zeros((80, 80), dtype=np.int8)
    d[:40, 40] = 100  # wall cells: centres x = 2.025, y up to 1.975
    g = grid_of(d)
    start, goal = np.array([1.025, 0.5]), np.array([3.025, 0.5])
    path = plan_path(g, start, goal, R, clearance_weight=0.0)
    assert path is not None
    blocked = inflate(g, RP)
    rows, cols = np.nonzero(blocked)
    corners = np.concatenate(
        [np.stack([(cols + dx) * RES, (rows + dy) * RES], 1) for dx in (0, 1) for dy in (0, 1)]
    )
    shortest = upper_hull_length(np.vstack([start, goal, corners]))
    # by hand: the blocked squares' top corners are (1.9, 2.05), (1.95, 2.1), (2.1, 2.1), (2.15, 2.05)
    assert shortest == pytest.approx(2 * math.hypot(0.875, 1.55) + 2 * math.sqrt(2) * RES + 3 * RES)
    assert shortest - 1e-9 <= length(path) <= 1.02 * shortest
    assert not crosses(path, blocked)


def test_clearance_cost_keeps_the_path_off_the_walls() -> None:
    """A U-turn around a wall's tip with 1 m of room: the plain shortest path grazes the inflated band,
    the default clearance cost keeps well clear of the tip."""
    d = np.zeros((60, 120), dtype=np.int8)
    d[0, :] = d[-1, :] = 100
    d[:, 0] = d[:, -1] = 100
    d[:40, 60] = 100
    g = grid_of(d)
    start, goal = cell_xy(5, 30), cell_xy(5, 90)
    soft = plan_path(g, start, goal, R)
    hard = plan_path(g, start, goal, R, clearance_weight=0.0)
    assert soft is not None and hard is not None
    wall = np.argwhere(d >= 65)[:, ::-1] * RES + RES / 2  # (x, y) of the occupied cell centres

    def min_clearance(path: np.ndarray) -> float:
        p = np.concatenate(
            [a + np.linspace(0, 1, 200)[:, None] * (b - a) for a, b in zip(path[:-1], path[1:])]
        )
        return float(np.linalg.norm(p[:, None] - wall[None], axis=2).min())

    assert R < min_clearance(hard) < R + 2 * RES
    assert min_clearance(soft) > R + 0.12
    assert length(soft) < 1.15 * length(hard)


def test_unreachable_goal_returns_none() -> None:
    d = np.zeros((60, 60), dtype=np.int8)
    d[20:40, 20] = d[20:40, 39] = 100
    d[20, 20:40] = d[39, 20:40] = 100  # a closed box
    g = grid_of(d)
    assert plan_path(g, cell_xy(5, 5), cell_xy(30, 30), R) is None
    # and out: a start inside the box cannot leave
    assert plan_path(g, cell_xy(30, 30), cell_xy(5, 5), R) is None
    # a gap narrower than the robot (2 free cells) is closed by the inflation
    d[30:32, 20] = 0
    assert plan_path(grid_of(d), cell_xy(5, 5), cell_xy(30, 30), R) is None
    # a wide door opens it
    d[26:36, 20] = 0
    assert plan_path(grid_of(d), cell_xy(5, 5), cell_xy(30, 30), R) is not None


def test_goal_on_an_obstacle_snaps_to_the_nearest_free_cell() -> None:
    d = np.zeros((60, 60), dtype=np.int8)
    d[:, 30] = 100
    g = grid_of(d)
    goal = cell_xy(30, 30)  # on the wall
    path = plan_path(g, cell_xy(30, 5), goal, R)
    assert path is not None
    # the nearest traversable cell on the start's side: 3 cells west of the wall (2 are inflated)
    assert np.allclose(path[-1], cell_xy(30, 27))
    # beyond the snap radius nothing is accepted
    d2 = np.zeros((60, 60), dtype=np.int8)
    d2[20:40, 20:40] = 100
    assert plan_path(grid_of(d2), cell_xy(5, 5), cell_xy(30, 30), R, goal_snap_radius_m=0.3) is None


def test_start_inside_the_inflation_escapes() -> None:
    d = np.zeros((40, 80), dtype=np.int8)
    d[:, 20] = 100
    g = grid_of(d)
    start = cell_xy(20, 21) + np.array([0.01, 0.0])  # 1 cell from the wall
    path = plan_path(g, start, cell_xy(20, 60), R)
    assert path is not None and np.allclose(path[0], start)
    # a start on a (noisy) occupied cell may leave as well, away from the wall
    path = plan_path(g, cell_xy(20, 20), cell_xy(20, 60), R)
    assert path is not None and path[-1][0] > path[0][0]


def test_unknown_cells() -> None:
    d = np.full((40, 80), -1, dtype=np.int8)
    d[15:25, :30] = 0
    g = grid_of(d)
    goal = cell_xy(20, 70)
    assert plan_path(g, cell_xy(20, 5), goal, R) is not None  # unknown is traversable by default
    assert plan_path(g, cell_xy(20, 5), goal, R, unknown_is_obstacle=True) is None


def test_rotated_grid_origin() -> None:
    """The path is in the map frame even when the grid origin is rotated and shifted."""
    d = np.zeros((40, 80), dtype=np.int8)
    d[:30, 40] = 100
    origin = Pose2(3.0, -2.0, 0.6)
    g = grid_of(d, origin)
    start = origin.transform_points(cell_xy(5, 10)[None])[0]
    goal = origin.transform_points(cell_xy(5, 70)[None])[0]
    path = plan_path(g, start, goal, R)
    assert path is not None
    assert np.allclose(path[0], start) and np.allclose(path[-1], goal)
    local = origin.inverse().transform_points(path)
    assert local[:, 1].max() > 30 * RES  # around the wall's tip, in the grid's own axes


def test_bad_input() -> None:
    g = grid_of(np.zeros((10, 10)))
    with pytest.raises(ValueError):
        plan_path(g, [np.nan, 0.1], [0.2, 0.2], R)
    with pytest.raises(ValueError):
        plan_path(grid_of(np.zeros((0, 0))), [0.1, 0.1], [0.2, 0.2], R)
    assert plan_path(g, [-5.0, -5.0], [0.2, 0.2], R) is None  # start outside the grid


def dense_cells(path: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows, cols and points of a sampling of the path every RES/20 (grid origin at 0)."""
    pts = [
        a + np.linspace(0, 1, int(np.linalg.norm(b - a) / (RES / 20)) + 2)[:, None] * (b - a)
        for a, b in zip(path[:-1], path[1:])
    ]
    p = np.concatenate(pts)
    return np.floor(p[:, 1] / RES).astype(int), np.floor(p[:, 0] / RES).astype(int), p


def crosses(path: np.ndarray, blocked: np.ndarray) -> bool:
    """True if a dense sampling of the path touches a blocked cell."""
    r, c, _ = dense_cells(path)
    return bool(blocked[r, c].any())


@st.composite
def random_world(draw):
    h, w = draw(st.integers(12, 36)), draw(st.integers(12, 36))
    seed = draw(st.integers(0, 2**31 - 1))
    density = draw(st.floats(0.0, 0.08))
    rng = np.random.default_rng(seed)
    d = np.where(rng.random((h, w)) < density, 100, 0).astype(np.int8)
    # a few wall segments
    for _ in range(draw(st.integers(0, 3))):
        if rng.random() < 0.5:
            r = rng.integers(0, h)
            c0, c1 = sorted(rng.integers(0, w, 2))
            d[r, c0 : c1 + 1] = 100
        else:
            c = rng.integers(0, w)
            r0, r1 = sorted(rng.integers(0, h, 2))
            d[r0 : r1 + 1, c] = 100
    start = rng.uniform([0, 0], [w * RES, h * RES])
    goal = rng.uniform([0, 0], [w * RES, h * RES])
    return d, start, goal


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(random_world(), st.sampled_from([0.0, 3.0]))
def test_paths_never_cross_inflated_cells(world, weight) -> None:
    d, start, goal = world
    g = grid_of(d)
    path = plan_path(g, start, goal, R, clearance_weight=weight, goal_snap_radius_m=0.0)
    blocked = inflate(g, RP)
    s_cell = (int(start[1] / RES), int(start[0] / RES))
    g_cell = (int(goal[1] / RES), int(goal[0] / RES))
    if path is None:
        # only when there is no 8-connected (no corner cutting) route through free cells
        cm = build_costmap(g, RP, start_xy=start, crop=False, clearance_weight=weight)
        dist, _ = cost_to_go(cm, s_cell)
        assert blocked[g_cell] or not np.isfinite(dist[g_cell])
        return
    assert np.allclose(path[0], start) and np.allclose(path[-1], goal)
    assert not blocked[g_cell]
    # A start inside the inflation may leave it through the cells of its escape disk (radius R + padding + 2 cells,
    # measured between cell centres), never through an occupied cell; everything else stays out.
    r, c, p = dense_cells(path)
    bad = blocked[r, c]
    if blocked[s_cell]:
        near = np.hypot(r - s_cell[0], c - s_cell[1]) * RES <= RP + 2 * RES + 1e-9
        bad &= ~near
    assert not bad.any(), p[bad][:5]
    assert not (d[r, c] >= 65).any() or d[s_cell] >= 65


@settings(max_examples=40, deadline=None)
@given(random_world())
def test_astar_is_optimal(world) -> None:
    """A* (octile heuristic) finds paths exactly as cheap as a Dijkstra search over the same graph."""
    d, start, goal = world
    cm = build_costmap(grid_of(d), R, crop=False)
    s = (int(start[1] / RES), int(start[0] / RES))
    g = (int(goal[1] / RES), int(goal[0] / RES))
    cells = astar(cm, s, g)
    if not cm.traversable[s] or not cm.traversable[g]:
        assert cells is None
        return
    dist, _ = cost_to_go(cm, s)
    if cells is None:
        assert not np.isfinite(dist[g])
        return
    c = np.asarray(cells)
    steps = np.abs(np.diff(c, axis=0))
    assert (steps.max(axis=1) == 1).all()  # 8-connected moves
    assert all(cm.traversable[tuple(x)] for x in c)
    step_len = np.hypot(steps[:, 0], steps[:, 1])
    cost = (step_len * 0.5 * (cm.cost[c[:-1, 0], c[:-1, 1]] + cm.cost[c[1:, 0], c[1:, 1]])).sum()
    assert cost == pytest.approx(dist[g], rel=1e-9, abs=1e-9)
