"""The generator's route planner (app/world/planner.py): its A* returns the textbook algorithm's path."""

from __future__ import annotations

import heapq
import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from app.world.planner import grid_path


def _reference_a_star(free, a, b, cost):
    """8-connected A* keyed by (row, col) tuples, every popped entry expanded (the planner before it was sped up)."""
    H, W = free.shape
    if not (free[a] and free[b]):
        return None
    openq = [(0.0, a)]
    came: dict = {}
    g = {a: 0.0}
    steps = [(-1, 0, 1.0), (1, 0, 1.0), (0, -1, 1.0), (0, 1, 1.0), (-1, -1, 1.414), (-1, 1, 1.414), (1, -1, 1.414), (1, 1, 1.414)]
    while openq:
        _, cur = heapq.heappop(openq)
        if cur == b:
            path = [cur]
            while cur in came:
                cur = came[cur]
                path.append(cur)
            return path[::-1]
        for dr, dc, step in steps:
            nr, nc = cur[0] + dr, cur[1] + dc
            if 0 <= nr < H and 0 <= nc < W and free[nr, nc]:
                if dr and dc and not (free[cur[0] + dr, cur[1]] and free[cur[0], cur[1] + dc]):
                    continue
                ng = g[cur] + step * (1.0 if cost is None else float(cost[nr, nc]))
                if ng < g.get((nr, nc), 1e18):
                    g[(nr, nc)] = ng
                    came[(nr, nc)] = cur
                    heapq.heappush(openq, (ng + math.hypot(nr - b[0], nc - b[1]), (nr, nc)))
    return None


def test_known_answers():
    free = np.ones((3, 5), dtype=bool)
    free[0:2, 2] = False  # a wall with a gap in the bottom row
    path = grid_path(free, (0, 0), (0, 4))
    assert path is not None and path[0] == (0, 0) and path[-1] == (0, 4)
    assert (2, 2) in path and all(free[p] for p in path)
    assert all(max(abs(p[0] - q[0]), abs(p[1] - q[1])) == 1 for p, q in zip(path, path[1:]))
    free[2, 2] = False
    assert grid_path(free, (0, 0), (0, 4)) is None  # no way through
    assert grid_path(free, (0, 2), (0, 4)) is None  # the start is blocked


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10_000), h=st.integers(2, 24), w=st.integers(2, 24), density=st.floats(0.0, 0.45),
       with_cost=st.booleans())
def test_the_same_path_as_the_reference_a_star(seed, h, w, density, with_cost):
    """Random grids, costs (1 or 4, as the planner's) and end points: the very same cells, ties included."""
    rng = np.random.default_rng(seed)
    free = rng.random((h, w)) >= density
    cost = np.where(rng.random((h, w)) < 0.3, 4.0, 1.0) if with_cost else None
    a = (int(rng.integers(h)), int(rng.integers(w)))
    b = (int(rng.integers(h)), int(rng.integers(w)))
    free[a] = free[b] = True
    assert grid_path(free, a, b, cost) == _reference_a_star(free, a, b, cost)


def _reference_pull(planner, pts):
    """String pulling by asking ``clear`` of each later point from the last one back (before it was vectorised)."""
    out, i = [pts[0]], 0
    while i < len(pts) - 1:
        j = len(pts) - 1
        while j > i + 1 and not planner.clear(pts[i], pts[j]):
            j -= 1
        out.append(pts[j])
        i = j
    return out


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(1, 60), chunk=st.sampled_from([1, 3, 16]))
def test_string_pulling_keeps_the_reference_points(seed, n, chunk):
    """Random walks (repeated points included) through a room with pillars: the same points, whatever the chunk."""
    from app.world.planner import Planner
    from app.world.types import Wall, World, WorldObject

    rng = np.random.default_rng(seed)
    world = World(
        name="pillars",
        walls=[Wall((0.0, 0.0), (6.0, 0.0)), Wall((6.0, 0.0), (6.0, 4.0)), Wall((6.0, 4.0), (0.0, 4.0)),
               Wall((0.0, 4.0), (0.0, 0.0))],
        objects=[WorldObject("ball", "play_ball", float(x), float(y)) for x, y in rng.uniform([1, 1], [5, 3], (3, 2))],
    )
    planner = Planner(world, clearance=0.15, res=0.1)
    steps = rng.choice([-0.1, 0.0, 0.1], size=(n, 2))
    pts = [tuple(p) for p in np.round(np.cumsum(steps, axis=0) + [3.0, 2.0], 3)]
    assert planner.pull_string(pts, chunk=chunk) == _reference_pull(planner, pts)


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 10_000), family=st.sampled_from(["rooms", "corridor", "lshape", "openplan"]),
       res=st.sampled_from([0.05, 0.1]))
def test_the_distance_grid_is_geos_distance_up_to_its_cap(seed, family, res):
    """A random world of each family: every cell's value is GEOS's distance from its centre to the blocking
    geometry where that is within the cap (and the planner's masks follow from those), ``inf`` only beyond it."""
    import shapely

    from app.world.generator import random_world
    from app.world.planner import Planner

    world = random_world(seed, family=family)
    planner = Planner(world, clearance=0.175, preferred=0.35, res=res)
    jj, ii = np.meshgrid(np.arange(planner.W), np.arange(planner.H))
    pts = np.c_[planner.x0 + (jj.ravel() + 0.5) * res, planner.y0 + (ii.ravel() + 0.5) * res]
    full = shapely.distance(planner.blocking, shapely.points(pts)).reshape(planner.H, planner.W)
    near = full <= planner.dist_cap
    assert np.array_equal(planner.dist[near], full[near])
    far = ~np.isfinite(planner.dist)
    assert np.all(full[far] > planner.dist_cap) and np.all(np.isfinite(planner.dist[near]))
    assert 0 < np.count_nonzero(far) < far.size  # the cut is exercised: cells on both sides of it
    assert np.array_equal(planner.free, full >= planner.clearance + res * 0.75)
    assert np.array_equal(planner.cost, np.where(full >= planner.preferred, 1.0, 4.0))
