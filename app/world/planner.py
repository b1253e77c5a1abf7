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

    Cells are flat indices of the grid padded with a blocked border (so a neighbour needs no bounds test) on
    Python lists; the heap breaks ties of equal ``f`` by that index, i.e. by ``(r, c)``, and an entry whose cell
    has since been reached more cheaply is skipped (that cell was expanded with its better ``g`` first;
    expanding it again could not improve a neighbour): the path is the one a tuple-keyed A* returns, faster."""
    H, W = free.shape
    if not (free[a] and free[b]):
        return None
    Wp = W + 2
    padded = np.zeros((H + 2, Wp), dtype=bool)
    padded[1:-1, 1:-1] = free
    ok = padded.ravel().tolist()
    c_pad = np.ones((H + 2, Wp), dtype=np.float64)  # no cost: every step at its length (x·1.0 is x exactly)
    if cost is not None:
        c_pad[1:-1, 1:-1] = cost
    step_cost = c_pad.ravel().tolist()
    br, bc = b[0] + 1, b[1] + 1
    goal = br * Wp + bc
    start = (a[0] + 1) * Wp + a[1] + 1
    g: dict[int, float] = {start: 0.0}
    came: dict[int, int] = {}
    openq: list[tuple[float, int]] = [(0.0, start)]
    straight = [(-Wp, -1, 0), (Wp, 1, 0), (-1, 0, -1), (1, 0, 1)]
    diagonal = [(-Wp - 1, -1, -1), (-Wp + 1, -1, 1), (Wp - 1, 1, -1), (Wp + 1, 1, 1)]
    hypot, heappush, heappop = math.hypot, heapq.heappush, heapq.heappop
    while openq:
        f, cur = heappop(openq)
        if cur == goal:
            path = [(cur // Wp - 1, cur % Wp - 1)]
            while cur in came:
                cur = came[cur]
                path.append((cur // Wp - 1, cur % Wp - 1))
            return path[::-1]
        r, c = divmod(cur, Wp)
        gc = g[cur]
        if f > gc + hypot(r - br, c - bc):  # a stale entry
            continue
        for dn, dr, dc in straight:
            n = cur + dn
            if not ok[n]:
                continue
            ng = gc + step_cost[n]
            if ng < g.get(n, 1e18):
                g[n] = ng
                came[n] = cur
                heappush(openq, (ng + hypot(r + dr - br, c + dc - bc), n))
        for dn, dr, dc in diagonal:
            n = cur + dn
            if not (ok[n] and ok[cur + dr * Wp] and ok[cur + dc]):
                continue
            ng = gc + 1.414 * step_cost[n]
            if ng < g.get(n, 1e18):
                g[n] = ng
                came[n] = cur
                heappush(openq, (ng + hypot(r + dr - br, c + dc - bc), n))
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
        #: the distance grid is exact up to this (m), every threshold the planner and the tour check compare it with
        self.dist_cap = max(preferred, clearance + 0.1, clearance + res)
        self.dist = self._distance_grid()
        # a margin of one cell so straight lines between neighbouring cell centres keep the clearance
        self.free = self.dist >= clearance + res * 0.75
        self.cost = np.where(self.dist >= preferred, 1.0, 4.0)

    def _distance_grid(self) -> NDArray[np.float64]:
        """``(H, W)`` distance (m) from each cell centre to the blocking geometry: exact (GEOS's) up to
        :attr:`dist_cap`; ``inf`` for the cells surely farther (outside the geometry grown by the cap and 5 cm,
        which covers the grown polygon's chords of its round corners, < 1 mm at these radii); 0 inside it.

        Only the cells between the geometry and that zone (a third to a half of a furnished world's) are measured:
        every comparison with a threshold up to the cap gives what the full grid gave."""
        res = self.res
        jj, ii = np.meshgrid(np.arange(self.W), np.arange(self.H))
        x, y = self.x0 + (jj.ravel() + 0.5) * res, self.y0 + (ii.ravel() + 0.5) * res
        shapely.prepare(self.blocking)
        zone = self.blocking.buffer(self.dist_cap + 0.05)
        shapely.prepare(zone)
        inside = shapely.contains_xy(self.blocking, x, y)  # strictly inside: GEOS's distance is 0 there
        near = shapely.contains_xy(zone, x, y) & ~inside
        dist = np.full(len(x), np.inf)
        dist[inside] = 0.0
        dist[near] = shapely.distance(self.blocking, shapely.points(x[near], y[near]))
        return dist.reshape(self.H, self.W)

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
        return self.pull_string([self.point(c) for c in cells])

    def pull_string(self, pts: list[tuple[float, float]], chunk: int = 16) -> list[tuple[float, float]]:
        """String pulling: from each kept point, the farthest later point reachable in a :meth:`clear` line.

        The same points as asking :meth:`clear` of each later point from the last one back, with the points'
        clearances computed once and the segments measured ``chunk`` at a time (one GEOS call each)."""
        n = len(pts)
        if n < 3:
            return list(pts)
        P = np.asarray(pts, dtype=np.float64)
        d_pt = shapely.distance(self.blocking, shapely.points(P))
        out = [pts[0]]
        i = 0
        while i < n - 1:
            j = i + 1
            for hi in range(n - 1, i + 1, -chunk):  # the later points, farthest first, a chunk at a time
                js = np.arange(hi, max(hi - chunk, i + 1), -1)
                need = np.minimum(np.minimum(self.preferred, d_pt[i]), d_pt[js])
                need = np.maximum(need - 0.01, self.clearance + 1e-3)
                same = np.all(P[js] == P[i], axis=1)  # a segment of no length is its point
                segs = shapely.linestrings(np.stack([np.broadcast_to(P[i], (len(js), 2)), P[js]], axis=1))
                d_seg = np.where(same, d_pt[i], shapely.distance(self.blocking, segs))
                ok = d_seg >= need
                if ok.any():
                    j = int(js[int(np.argmax(ok))])
                    break
            out.append(pts[j])
            i = j
        return out
