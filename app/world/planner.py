"""Route planning on a grid over a world's blocking geometry (the ``tour`` routes of generated worlds).

:class:`Planner` forbids cells within ``clearance`` of anything the robot cannot drive through,
makes cells within ``preferred`` dearer, plans 8-connected A* (:func:`grid_path`) and shortens the
path by string pulling.

Example:
    >>> planner = Planner(world, clearance=0.175)
    >>> planner.plan((0.5, 0.5), (4.0, 3.0))        # [(x, y), ...] world frame, or None
"""

from __future__ import annotations

import heapq
import math

import numpy as np
import shapely
from numpy.typing import NDArray
from shapely.geometry import LineString, Point
from shapely.ops import unary_union

from app.world.types import World

__all__ = ["Planner", "grid_path"]


def grid_path(
    free: NDArray[np.bool_], a: tuple[int, int], b: tuple[int, int], cost: NDArray[np.float64] | None = None
) -> list[tuple[int, int]] | None:
    """8-connected A* on a boolean grid (row, col); ``cost`` (≥ 1) multiplies the step length.

    Cells are flat indices ``r·W + c`` on Python lists (the heap breaks ties of equal ``f`` by that index,
    i.e. by ``(r, c)``), and an entry whose cell has since been reached more cheaply is skipped (that cell was
    expanded with its better ``g`` first; expanding it again could not improve a neighbour): the path is the
    one a tuple-keyed A* returns, faster."""
    H, W = free.shape
    if not (free[a] and free[b]):
        return None
    ok = free.ravel().tolist()
    step_cost = None if cost is None else np.asarray(cost, dtype=np.float64).ravel().tolist()
    br, bc = b
    goal = br * W + bc
    start = a[0] * W + a[1]
    g: dict[int, float] = {start: 0.0}
    came: dict[int, int] = {}
    openq: list[tuple[float, int]] = [(0.0, start)]
    steps = [(-1, 0, 1.0), (1, 0, 1.0), (0, -1, 1.0), (0, 1, 1.0), (-1, -1, 1.414), (-1, 1, 1.414), (1, -1, 1.414), (1, 1, 1.414)]
    hypot, heappush, heappop = math.hypot, heapq.heappush, heapq.heappop
    while openq:
        f, cur = heappop(openq)
        if cur == goal:
            path = [(cur // W, cur % W)]
            while cur in came:
                cur = came[cur]
                path.append((cur // W, cur % W))
            return path[::-1]
        r, c = divmod(cur, W)
        gc = g[cur]
        if f > gc + hypot(r - br, c - bc):  # a stale entry
            continue
        for dr, dc, step in steps:
            nr, nc = r + dr, c + dc
            if not (0 <= nr < H and 0 <= nc < W):
                continue
            n = cur + dr * W + dc
            if not ok[n] or (dr and dc and not (ok[cur + dr * W] and ok[cur + dc])):
                continue
            ng = gc + step * (1.0 if step_cost is None else step_cost[n])
            if ng < g.get(n, 1e18):
                g[n] = ng
                came[n] = cur
                heappush(openq, (ng + hypot(nr - br, nc - bc), n))
    return None


class Planner:
    """Grid planner over the world's blocking geometry: cells within ``clearance`` of anything are
    forbidden, cells within ``preferred`` cost more, so routes keep well away from obstacles where the
    space allows and squeeze through doorways where it does not."""

    def __init__(self, world: World, clearance: float, preferred: float = 0.35, res: float = 0.05) -> None:
        xmin, ymin, xmax, ymax = world.bounds()
        self.res, self.x0, self.y0 = res, xmin, ymin
        self.W = int(math.ceil((xmax - xmin) / res)) + 1
        self.H = int(math.ceil((ymax - ymin) / res)) + 1
        self.blocking = unary_union([g for _, g in world.blocking_geometry()])
        self.clearance, self.preferred = clearance, preferred
        jj, ii = np.meshgrid(np.arange(self.W), np.arange(self.H))
        pts = np.c_[xmin + (jj.ravel() + 0.5) * res, ymin + (ii.ravel() + 0.5) * res]
        self.dist = shapely.distance(self.blocking, shapely.points(pts)).reshape(self.H, self.W)
        # a margin of one cell so straight lines between neighbouring cell centres keep the clearance
        self.free = self.dist >= clearance + res * 0.75
        self.cost = np.where(self.dist >= preferred, 1.0, 4.0)

    def cell(self, x: float, y: float) -> tuple[int, int]:
        return (int((y - self.y0) / self.res), int((x - self.x0) / self.res))

    def point(self, c: tuple[int, int]) -> tuple[float, float]:
        return (self.x0 + (c[1] + 0.5) * self.res, self.y0 + (c[0] + 0.5) * self.res)

    def clear(self, a: tuple[float, float], b: tuple[float, float]) -> bool:
        """The segment keeps ``preferred`` clearance, or at least as much as its end points have."""
        need = min(self.preferred, self.blocking.distance(Point(a)), self.blocking.distance(Point(b)))
        need = max(need - 0.01, self.clearance + 1e-3)
        seg = LineString([a, b]) if a != b else Point(a)
        return self.blocking.distance(seg) >= need

    def nearest_free(self, x: float, y: float, max_r: float = 1.5) -> tuple[int, int] | None:
        r0, c0 = self.cell(x, y)
        k = int(max_r / self.res)
        rs = slice(max(0, r0 - k), min(self.H, r0 + k + 1))
        cs = slice(max(0, c0 - k), min(self.W, c0 + k + 1))
        sub = self.free[rs, cs] & (self.dist[rs, cs] >= min(self.preferred, self.clearance + 0.1))
        if not sub.any():
            sub = self.free[rs, cs]
            if not sub.any():
                return None
        ii, jj = np.nonzero(sub)
        ii, jj = ii + rs.start, jj + cs.start
        k = int(np.argmin((ii - r0) ** 2 + (jj - c0) ** 2))
        return (int(ii[k]), int(jj[k]))

    def plan(self, a: tuple[float, float], b: tuple[float, float]) -> list[tuple[float, float]] | None:
        ca, cb = self.nearest_free(*a), self.nearest_free(*b)
        if ca is None or cb is None:
            return None
        cells = grid_path(self.free, ca, cb, self.cost)
        if cells is None:
            return None
        pts = [self.point(c) for c in cells]
        # string pulling: keep the farthest point reachable in a straight, clear line
        out = [pts[0]]
        i = 0
        while i < len(pts) - 1:
            j = len(pts) - 1
            while j > i + 1 and not self.clear(pts[i], pts[j]):
                j -= 1
            out.append(pts[j])
            i = j
        return out
