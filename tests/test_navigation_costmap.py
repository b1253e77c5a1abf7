"""Inflation and cost maps: known answers."""

from __future__ import annotations

import numpy as np
import pytest

from app.ocslam.messages import OccupancyGrid
from app.ocslam.navigation import build_costmap, inflate
from app.ocslam.navigation.costmap import segment_cells
from app.ocslam.se2 import Pose2

RES = 0.05


def grid_of(data: np.ndarray, origin: Pose2 = Pose2()) -> OccupancyGrid:
    return OccupancyGrid(RES, origin, np.asarray(data, dtype=np.int8))


def single_cell(value: int = 100, n: int = 11) -> OccupancyGrid:
    d = np.zeros((n, n), dtype=np.int8)
    d[n // 2, n // 2] = value
    return grid_of(d)


def test_inflation_of_one_cell_is_a_disk() -> None:
    # cells whose centre lies within 0.105 m (2.1 cells) of the occupied centre:
    # i² + j² <= 4.41  ->  the centre, 4 at 1, 4 diagonals (√2), 4 at 2  = 13
    blocked = inflate(single_cell(), 0.105)
    assert blocked.sum() == 13
    i, j = np.nonzero(blocked)
    assert ((i - 5) ** 2 + (j - 5) ** 2 <= 4.41).all()
    # a radius just under 2 cells loses the 4 cells at distance 2; exactly 2 cells keeps them
    assert inflate(single_cell(), 0.099).sum() == 9
    assert inflate(single_cell(), 0.10).sum() == 13
    assert inflate(single_cell(), 0.0).sum() == 1


def test_inflation_thresholds_and_unknown() -> None:
    assert inflate(single_cell(64), 0.105).sum() == 0  # below the occupied threshold
    assert inflate(single_cell(65), 0.105).sum() == 13
    assert inflate(single_cell(50), 0.105, occupied_threshold=50).sum() == 13
    unk = single_cell(-1)
    assert inflate(unk, 0.105).sum() == 0
    assert inflate(unk, 0.105, unknown_is_obstacle=True).sum() == 13


def test_inflation_is_independent_of_the_origin() -> None:
    d = np.zeros((11, 11), dtype=np.int8)
    d[5, 5] = 100
    a = inflate(grid_of(d), 0.105)
    b = inflate(grid_of(d, Pose2(-3.0, 2.0, 0.7)), 0.105)
    assert (a == b).all()


def test_inflation_rejects_bad_radius() -> None:
    with pytest.raises(ValueError):
        inflate(single_cell(), float("nan"))
    with pytest.raises(ValueError):
        inflate(single_cell(), -0.1)


def test_costmap_clearance_cost_and_crop() -> None:
    d = np.full((200, 200), -1, dtype=np.int8)
    d[50:80, 60:100] = 0
    d[50:80, 60] = 100  # a wall on the west side of the known patch
    cm = build_costmap(grid_of(d), 0.105, clearance_m=0.3, clearance_weight=3.0, crop_margin_cells=5)
    # the crop holds the known patch plus the margin (5 + ceil(0.405 / 0.05) = 14 cells)
    assert cm.row0 == 50 - 14 and cm.col0 == 60 - 14
    assert cm.shape == (30 + 28, 40 + 28)
    r = 65 - cm.row0
    wall = 60 - cm.col0
    assert cm.blocked[r, wall : wall + 3].all() and not cm.blocked[r, wall + 3]
    # the cost decays from 1 + w at the inflation edge to 1 beyond radius + clearance
    row_cost = cm.cost[r, wall + 3 : wall + 15]
    assert (np.diff(row_cost) <= 1e-12).all()
    assert row_cost[0] > 3.0 and row_cost[-1] == 1.0
    # map-frame round trip of cell centres
    cells = np.array([[r, wall + 4]])
    assert (cm.to_cells(cm.to_xy(cells)) == cells).all()


def test_escape_lets_a_start_inside_the_inflation_leave() -> None:
    d = np.zeros((40, 40), dtype=np.int8)
    d[:, 20] = 100
    g = grid_of(d)
    start = np.array([21.5 * RES, 20.5 * RES])  # one cell east of the wall: inside the inflation band
    plain = build_costmap(g, 0.105, crop=False)
    assert not plain.traversable[20, 21]
    cm = build_costmap(g, 0.105, start_xy=start, crop=False)
    assert cm.traversable[20, 21] and cm.traversable[20, 22]
    assert not cm.traversable[20, 20]  # never the occupied cells themselves
    assert not cm.traversable[20, 19]  # nor cells of the disk behind the wall
    assert cm.cost[20, 21] >= 10.0  # leaving costs: the path gets out of the band quickly


def test_segment_cells_is_a_supercover() -> None:
    a, b = np.array([0.5, 0.5]), np.array([3.5, 2.5])  # (col, row) continuous cell coordinates
    cells = {tuple(c) for c in segment_cells(a, b)}
    # dense sampling never leaves the returned cells
    t = np.linspace(0, 1, 5001)[:, None]
    p = a + t * (b - a)
    dense = {(int(np.floor(y)), int(np.floor(x))) for x, y in p}
    assert dense <= cells
