"""The log-odds grid on a synthetic room."""

from __future__ import annotations

import numpy as np

from app.ocslam.se2 import Pose2
from app.ocslam.slam.grid import LogOddsGrid
from app.ocslam.slam.synthetic import room_world, simulate_scan


def _insert(grid, pose, segs, sign=1.0):
    sc = simulate_scan(pose, segs, range_max=3.5)
    r = sc.ranges
    hit = np.isfinite(r)
    rr = np.where(hit, r, 3.0)
    a = sc.angles
    ends = pose.transform_points(np.stack([rr * np.cos(a), rr * np.sin(a)], 1))
    grid.scan_update(np.array([pose.x, pose.y]), ends, hit, sign)


def _sample_walls(segs, step=0.01):
    pts = []
    for x0, y0, x1, y1 in segs:
        n = max(2, int(np.hypot(x1 - x0, y1 - y0) / step))
        f = np.linspace(0, 1, n)[:, None]
        pts.append(np.array([x0, y0]) + f * np.array([x1 - x0, y1 - y0]))
    return np.vstack(pts)


def test_room_map_walls_free_unknown():
    segs = room_world()
    g = LogOddsGrid(0.05)
    poses = [Pose2(2.0, 2.0, 0.3), Pose2(2.5, 4.0, 1.0), Pose2(7.0, 3.0, -2.0), Pose2(8.0, 5.5, 2.5), Pose2(5.5, 6.5, 0.0)]
    for p in poses:
        _insert(g, p, segs)
    msg = g.to_msg()
    assert msg.data.dtype == np.int8
    assert set(np.unique(msg.data)).issubset(set(range(-1, 101)))
    # cells on walls that were observed are occupied (allow a few at grazing angles / corners)
    walls = _sample_walls(segs)
    rc = msg.world_to_cell(walls)
    inside = (rc[:, 0] >= 0) & (rc[:, 0] < msg.height) & (rc[:, 1] >= 0) & (rc[:, 1] < msg.width)
    v = msg.data[rc[inside, 0], rc[inside, 1]]
    seen = v >= 0
    assert seen.sum() > 300
    # a wall point lies in an occupied cell, or within one cell of one (points exactly on cell borders)
    occ = msg.data >= 65
    occ_d = occ.copy()
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            occ_d |= np.roll(np.roll(occ, dr, 0), dc, 1)
    assert occ_d[rc[inside, 0][seen], rc[inside, 1][seen]].mean() > 0.97
    # free space around each pose is free
    for p in poses:
        r, c = msg.world_to_cell(np.array([[p.x, p.y]]))[0]
        assert 0 <= msg.data[r, c] < 50  # observed, and more likely free than not
    # outside the room is never observed as free (walls block the rays)
    outside = np.array([[-1.0, 4.0], [11.0, 4.0], [5.0, -1.0], [5.0, 9.0]])
    rc = msg.world_to_cell(outside)
    for r, c in rc:
        if 0 <= r < msg.height and 0 <= c < msg.width:
            assert msg.data[r, c] in (-1,) or msg.data[r, c] >= 50
    # occupied cells are all near a wall
    centers = msg.cell_centers()[occ]
    d = np.min(np.hypot(*(centers[:, None, :] - walls[None, ::5, :]).transpose(2, 0, 1)), axis=1)
    assert np.all(d < 0.05 * 1.5)


def test_growth_keeps_cells_and_removal_is_exact():
    segs = room_world()
    g = LogOddsGrid(0.05, grow_margin_m=0.5)
    p1 = Pose2(2.0, 2.0, 0.0)
    _insert(g, p1, segs)
    probe = np.array([[2.5, 2.0], [0.02, 2.0]])
    before = g.to_msg()
    v1 = before.data[tuple(before.world_to_cell(probe).T)]
    _insert(g, Pose2(8.5, 6.5, 0.0), segs)  # far away: the grid grows
    after = g.to_msg()
    assert after.width * after.height > before.width * before.height
    v2 = after.data[tuple(after.world_to_cell(probe).T)]
    assert np.array_equal(v1, v2)
    _insert(g, Pose2(8.5, 6.5, 0.0), segs, sign=-1.0)
    _insert(g, p1, segs, sign=-1.0)
    assert np.all(g.log_odds == 0) and np.all(g.observed == 0)
    assert np.all(g.to_msg().data == -1)


def test_message_cells_are_reused_until_the_grid_changes():
    segs = room_world()
    g = LogOddsGrid(0.05)
    _insert(g, Pose2(0.0, 0.0, 0.0), segs)
    a, b = g.to_msg(1.0), g.to_msg(2.0)
    assert b.data is a.data and b.stamp == 2.0  # the same cells, each message its own stamp
    assert not a.data.flags.writeable  # shared: nobody may write into them
    before = a.data.copy()
    _insert(g, Pose2(0.5, 0.2, 0.3), segs)  # a scan (and maybe growth) changes the cells
    c = g.to_msg(3.0)
    assert c.data is not a.data
    fresh = LogOddsGrid(0.05)
    _insert(fresh, Pose2(0.0, 0.0, 0.0), segs)
    _insert(fresh, Pose2(0.5, 0.2, 0.3), segs)
    np.testing.assert_array_equal(c.data, fresh.to_msg().data)  # what an uncached grid gives
    np.testing.assert_array_equal(a.data, before)  # the old message is untouched
