"""Grid path planning on a :class:`~app.ocslam.navigation.costmap.CostMap`.

* :func:`astar`: A* from one cell to another, 8-connected (no corner cutting: a diagonal move needs both
  orthogonal neighbours traversable), octile heuristic (admissible: every cell cost is ``>= 1``).
* :func:`cost_to_go`: the same cost from one cell to *all* cells (Dijkstra, scipy's C implementation),
  used by the frontier explorer to rank every frontier with one search.
* :func:`smooth_path`: line-of-sight shortcutting of a cell path that never enters an untraversable
  cell and never passes closer to obstacles (higher clearance cost) than the part of the path it replaces.
* :func:`plan_path`: the public entry point, map-frame points in, ``(N, 2)`` map-frame waypoints out.

A move between neighbouring cells ``a → b`` costs ``len · (cost[a] + cost[b]) / 2`` metres, ``len`` being
``res`` or ``√2·res``.
"""

from __future__ import annotations

import heapq
import math
from typing import TypedDict

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from app.ocslam.messages import OccupancyGrid
from app.ocslam.navigation.costmap import OCCUPIED_THRESHOLD, CostMap, build_costmap, segment_cells

SQRT2 = math.sqrt(2.0)
_FOUR = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], dtype=bool)


def components(traversable: NDArray[np.bool_]) -> NDArray[np.int32]:
    """``(H, W)`` labels of the connected regions a path can join (0 = not traversable).

    Since diagonal moves need both orthogonal neighbours, 8-connected paths connect exactly the
    4-connected components.
    """
    labels, _ = ndimage.label(traversable, structure=_FOUR)
    return labels.astype(np.int32, copy=False)


def astar(cm: CostMap, start: tuple[int, int], goal: tuple[int, int]) -> list[tuple[int, int]] | None:
    """A* over traversable crop cells. Returns the ``(row, col)`` cells from start to goal, or None.

    The start and goal cells must be traversable (see :func:`build_costmap`'s escape for a start
    inside the inflation band).
    """
    h, w = cm.shape
    (sr, sc), (gr, gc) = start, goal
    for r, c in (start, goal):
        if not (0 <= r < h and 0 <= c < w) or not cm.traversable[r, c]:
            return None
    if start == goal:
        return [start]
    wp = w + 2
    # padded with an untraversable border: no bound checks in the loop
    trav = np.pad(cm.traversable, 1, constant_values=False).ravel().tolist()
    cost = np.pad(cm.cost, 1, constant_values=1.0).ravel().tolist()
    s = (sr + 1) * wp + sc + 1
    g = (gr + 1) * wp + gc + 1
    gr1, gc1 = gr + 1, gc + 1
    # (flat offset, length, orthogonal neighbour offsets that must be free for a diagonal)
    moves = (
        (1, 1.0, ()),
        (-1, 1.0, ()),
        (wp, 1.0, ()),
        (-wp, 1.0, ()),
        (wp + 1, SQRT2, (wp, 1)),
        (wp - 1, SQRT2, (wp, -1)),
        (-wp + 1, SQRT2, (-wp, 1)),
        (-wp - 1, SQRT2, (-wp, -1)),
    )
    k = SQRT2 - 2.0
    n = len(trav)
    gscore = [math.inf] * n
    parent = [-1] * n
    closed = bytearray(n)
    gscore[s] = 0.0
    heap: list[tuple[float, float, int]] = [(0.0, 0.0, s)]
    push, pop = heapq.heappush, heapq.heappop
    while heap:
        _, _, u = pop(heap)
        if closed[u]:
            continue
        if u == g:
            break
        closed[u] = 1
        gu = gscore[u]
        cu = cost[u]
        for off, length, ortho in moves:
            v = u + off
            if not trav[v] or closed[v]:
                continue
            if ortho and not (trav[u + ortho[0]] and trav[u + ortho[1]]):
                continue
            nv = gu + length * 0.5 * (cu + cost[v])
            if nv < gscore[v]:
                gscore[v] = nv
                parent[v] = u
                r, c = divmod(v, wp)
                dr = abs(r - gr1)
                dc = abs(c - gc1)
                hv = dr + dc + k * (min(dc, dr))
                push(heap, (nv + hv, hv, v))
    if parent[g] < 0:
        return None
    out = []
    v = g
    while v != s:
        r, c = divmod(v, wp)
        out.append((r - 1, c - 1))
        v = parent[v]
    out.append(start)
    out.reverse()
    return out


def _graph(cm: CostMap) -> csr_matrix:
    """Sparse undirected graph of the 8-connected moves between traversable cells (edge = move cost)."""
    h, w = cm.shape
    trav = cm.traversable
    cost = cm.cost
    idx = np.arange(h * w).reshape(h, w)
    rows, cols, wts = [], [], []

    def add(
        src: tuple[slice, slice], dst: tuple[slice, slice], length: float, extra: NDArray[np.bool_] | None
    ):
        ok = trav[src] & trav[dst]
        if extra is not None:
            ok &= extra
        rows.append(idx[src][ok])
        cols.append(idx[dst][ok])
        wts.append(length * 0.5 * (cost[src][ok] + cost[dst][ok]))

    a, b = slice(0, -1), slice(1, None)
    al = slice(None)
    add((al, a), (al, b), 1.0, None)  # right
    add((a, al), (b, al), 1.0, None)  # down (+row)
    add((a, a), (b, b), SQRT2, trav[b, a] & trav[a, b])  # +row +col
    add((a, b), (b, a), SQRT2, trav[b, b] & trav[a, a])  # +row -col
    r = np.concatenate(rows)
    c = np.concatenate(cols)
    wgt = np.concatenate(wts)
    return csr_matrix((wgt, (r, c)), shape=(h * w, h * w))


def cost_to_go(cm: CostMap, start: tuple[int, int]) -> tuple[NDArray[np.float64], NDArray[np.int32]]:
    """Dijkstra from ``start`` over the same moves and costs as :func:`astar`.

    Returns ``(dist, pred)``: ``(H, W)`` path cost in cells (multiply by ``res`` for metres; ``inf`` when
    unreachable) and ``(H·W,)`` flat predecessor indices (``< 0`` at the start and unreachable cells).
    """
    h, w = cm.shape
    r, c = start
    if not (0 <= r < h and 0 <= c < w) or not cm.traversable[r, c]:
        return np.full((h, w), np.inf), np.full(h * w, -9999, dtype=np.int32)
    dist, pred = dijkstra(_graph(cm), directed=False, indices=r * w + c, return_predecessors=True)
    return dist.reshape(h, w), pred


def extract_path(pred: NDArray[np.int32], width: int, goal: tuple[int, int]) -> list[tuple[int, int]]:
    """Cells from the Dijkstra root to ``goal`` following ``pred`` (from :func:`cost_to_go`)."""
    v = goal[0] * width + goal[1]
    out = []
    while v >= 0:
        out.append(divmod(int(v), width))
        v = pred[v]
    out.reverse()
    return out


def line_of_sight(
    cm: CostMap, a: NDArray[np.float64], b: NDArray[np.float64], max_cost: float = math.inf
) -> bool:
    """True when every cell the segment ``a → b`` (continuous crop coordinates ``(col, row)``) touches
    is traversable and costs at most ``max_cost``."""
    cells = segment_cells(a, b)
    h, w = cm.shape
    if cells.min() < 0 or cells[:, 0].max() >= h or cells[:, 1].max() >= w:
        return False
    if not cm.traversable[cells[:, 0], cells[:, 1]].all():
        return False
    return bool(cm.cost[cells[:, 0], cells[:, 1]].max() <= max_cost + 1e-9)


def smooth_path(
    cm: CostMap,
    cells: list[tuple[int, int]],
    start_local: NDArray[np.float64] | None = None,
    goal_local: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """Greedy line-of-sight shortcutting of a cell path.

    Args:
        cells: ``(row, col)`` crop cells from :func:`astar` / :func:`extract_path`.
        start_local, goal_local: exact end points in continuous crop coordinates (``(col, row)``); default
            the end cells' centres.

    Returns:
        ``(N, 2)`` waypoints in continuous crop coordinates ``(col, row)``. A shortcut replaces the cells
        ``i..j`` only if the straight segment touches traversable cells whose clearance cost does not
        exceed the highest cost along ``i..j``: smoothing never brings the path closer to obstacles.
    """
    arr = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
    pts = arr[:, ::-1].astype(np.float64) + 0.5
    if start_local is not None:
        pts[0] = start_local
    if goal_local is not None:
        pts[-1] = goal_local
    n = len(pts)
    if n <= 2:
        return pts
    cell_cost = cm.cost[arr[:, 0], arr[:, 1]]
    out = [pts[0]]
    i = 0
    while i < n - 1:
        best = i + 1
        running = max(cell_cost[i], cell_cost[i + 1])
        for j in range(i + 2, n):
            running = max(running, cell_cost[j])
            if line_of_sight(cm, pts[i], pts[j], running):
                best = j
            else:
                break
        out.append(pts[best])
        i = best
    return cut_corners(cm, drop_collinear(np.asarray(out)))


def _max_cost(cm: CostMap, a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    cells = segment_cells(a, b)
    h, w = cm.shape
    cells = cells[(cells[:, 0] >= 0) & (cells[:, 0] < h) & (cells[:, 1] >= 0) & (cells[:, 1] < w)]
    return float(cm.cost[cells[:, 0], cells[:, 1]].max()) if len(cells) else math.inf


def cut_corners(
    cm: CostMap, pts: NDArray[np.float64], rounds: int = 3, steps: int = 6
) -> NDArray[np.float64]:
    """Shorten a polyline (continuous crop coordinates) by cutting its corners.

    Each interior vertex ``v`` between ``a`` and ``b`` is replaced by the cut ``p = v + t(a − v)``,
    ``q = v + t(b − v)`` with the largest ``t`` (bisection) whose segment ``p → q`` passes
    :func:`line_of_sight` at no more than the highest cost along ``a → v → b``; ``t = 1`` removes the
    vertex. This pulls the grid-bound vertices of :func:`smooth_path` towards the taut (any-angle) path.
    """
    for _ in range(rounds):
        if len(pts) <= 2:
            return pts
        out = [pts[0]]
        changed = False
        for i in range(1, len(pts) - 1):
            a, v, b = out[-1], pts[i], pts[i + 1]
            limit = max(_max_cost(cm, a, v), _max_cost(cm, v, b))
            if line_of_sight(cm, a, b, limit):
                changed = True
                continue
            lo, hi = 0.0, 1.0
            for _ in range(steps):
                t = 0.5 * (lo + hi)
                if line_of_sight(cm, v + t * (a - v), v + t * (b - v), limit):
                    lo = t
                else:
                    hi = t
            if lo > 0.0 and lo * min(np.hypot(*(a - v)), np.hypot(*(b - v))) > 0.05:
                out.extend([v + lo * (a - v), v + lo * (b - v)])
                changed = True
            else:
                out.append(v)
        out.append(pts[-1])
        pts = drop_collinear(np.asarray(out))
        if not changed:
            break
    return pts


def drop_collinear(pts: NDArray[np.float64], tol: float = 1e-6) -> NDArray[np.float64]:
    """Remove interior points of ``(N, 2)`` that lie on the straight continuation of their neighbours
    (same direction), which leaves the polyline's geometry unchanged."""
    if len(pts) <= 2:
        return pts
    d1 = pts[1:-1] - pts[:-2]
    d2 = pts[2:] - pts[1:-1]
    cross = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    dot = (d1 * d2).sum(axis=1)
    scale = np.linalg.norm(d1, axis=1) * np.linalg.norm(d2, axis=1)
    keep_mid = ~((np.abs(cross) <= tol * np.maximum(scale, 1e-12)) & (dot > 0))
    return pts[np.concatenate([[True], keep_mid, [True]])]


def local_to_xy(cm: CostMap, local: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(N, 2)`` continuous crop coordinates ``(col, row)`` → ``(N, 2)`` map-frame points."""
    p = np.asarray(local, dtype=np.float64).reshape(-1, 2).copy()
    p[:, 0] += cm.col0
    p[:, 1] += cm.row0
    return cm.origin.transform_points(p * cm.resolution)


def snap_goal(
    cm: CostMap, goal_xy: NDArray[np.float64], labels: NDArray[np.int32], label: int, radius_m: float
) -> tuple[int, int] | None:
    """The cell with ``labels == label`` nearest to ``goal_xy`` within ``radius_m``, or None."""
    gl = cm.to_local(goal_xy[None])[0]  # (col, row)
    k = int(math.ceil(radius_m / cm.resolution)) + 1
    h, w = cm.shape
    c_mid, r_mid = int(math.floor(gl[0])), int(math.floor(gl[1]))
    r0, r1 = max(0, r_mid - k), min(h, r_mid + k + 1)
    c0, c1 = max(0, c_mid - k), min(w, c_mid + k + 1)
    if r0 >= r1 or c0 >= c1:
        return None
    rr, cc = np.mgrid[r0:r1, c0:c1]
    d = np.hypot(cc + 0.5 - gl[0], rr + 0.5 - gl[1]) * cm.resolution
    ok = (labels[r0:r1, c0:c1] == label) & (d <= radius_m)
    if not ok.any():
        return None
    d = np.where(ok, d, np.inf)
    i = int(np.argmin(d))
    return int(rr.ravel()[i]), int(cc.ravel()[i])


class PlanOptions(TypedDict, total=False):
    """The tuning keywords of :func:`plan_path` (what a :class:`~app.ocslam.navigation.goto.GoToController`
    passes through)."""

    goal_snap_radius_m: float
    inflation_padding_m: float
    clearance_m: float
    clearance_weight: float
    occupied_threshold: int
    smooth: bool


def plan_path(
    grid: OccupancyGrid,
    start_xy: ArrayLike,
    goal_xy: ArrayLike,
    robot_radius_m: float,
    *,
    unknown_is_obstacle: bool = False,
    goal_snap_radius_m: float = 0.3,
    inflation_padding_m: float = 0.025,
    clearance_m: float = 0.3,
    clearance_weight: float = 3.0,
    occupied_threshold: int = OCCUPIED_THRESHOLD,
    extra_obstacles_xy: ArrayLike | None = None,
    smooth: bool = True,
) -> NDArray[np.float64] | None:
    """Plan a collision-free path on the SLAM grid.

    A* on the grid inflated by ``robot_radius_m + inflation_padding_m`` (8-connected, octile heuristic,
    soft clearance cost), then line-of-sight smoothing and corner cutting.

    Args:
        grid: the SLAM occupancy grid (``map`` frame).
        start_xy, goal_xy: ``(2,)`` points in the ``map`` frame. A start inside the inflation band may
            leave it; a goal on a blocked (or unreachable) cell is snapped to the nearest reachable free
            cell within ``goal_snap_radius_m``.
        inflation_padding_m: added to the radius for the inflation: inflation is measured between cell
            centres, while an obstacle's surface and the robot's centre may each lie up to half a cell
            off them. The default (half a 5 cm cell) rounds corners without closing axis-aligned gaps
            that the bare radius leaves open.
        unknown_is_obstacle: unknown cells are inflated obstacles; otherwise they are traversable.
        clearance_weight: 0 gives plain shortest paths hugging the inflation band.
        extra_obstacles_xy: ``(M, 2)`` virtual obstacle points (see :func:`build_costmap`).

    Returns:
        ``(N, 2)`` waypoints in the ``map`` frame, from ``start_xy`` to the (snapped) goal, ``N >= 2``;
        None when the goal is unreachable (or the start lies outside the grid).

    Raises:
        ValueError: non-finite start/goal or radius.
    """
    start = np.asarray(start_xy, dtype=np.float64).reshape(2)
    goal = np.asarray(goal_xy, dtype=np.float64).reshape(2)
    if not (np.isfinite(start).all() and np.isfinite(goal).all()):
        raise ValueError(f"start and goal must be finite, got {start} and {goal}")
    cm = build_costmap(
        grid,
        robot_radius_m + inflation_padding_m,
        start_xy=start,
        keep_xy=goal[None],
        occupied_threshold=occupied_threshold,
        unknown_is_obstacle=unknown_is_obstacle,
        clearance_m=clearance_m,
        clearance_weight=clearance_weight,
        extra_obstacles_xy=extra_obstacles_xy,
    )
    s_cell = cm.to_cells(start[None])[0]
    if not cm.in_bounds(s_cell[None])[0]:
        return None
    s = (int(s_cell[0]), int(s_cell[1]))
    labels = components(cm.traversable)
    lab = labels[s]
    if lab == 0:
        return None
    g_cell = cm.to_cells(goal[None])[0]
    goal_local: NDArray[np.float64] | None
    # a goal must be a truly free cell: the start's escape disk inside the inflation is no destination
    goal_ok = labels == lab
    goal_ok &= ~cm.blocked
    if cm.in_bounds(g_cell[None])[0] and goal_ok[g_cell[0], g_cell[1]]:
        g = (int(g_cell[0]), int(g_cell[1]))
        goal_local = cm.to_local(goal[None])[0]
    else:
        snapped = snap_goal(cm, goal, goal_ok.astype(np.int32), 1, goal_snap_radius_m)
        if snapped is None:
            return None
        g = snapped
        goal_local = None  # the snapped cell's centre
    cells = astar(cm, s, g)
    if cells is None:  # cannot happen for one component, but never trust it blindly
        return None
    start_local = cm.to_local(start[None])[0]
    if smooth:
        local = smooth_path(cm, cells, start_local, goal_local)
    else:
        local = np.asarray(cells, dtype=np.float64)[:, ::-1] + 0.5
        local[0] = start_local
        if goal_local is not None:
            local[-1] = goal_local
    if len(local) == 1:
        end = goal_local if goal_local is not None else local[0]
        local = np.stack([start_local, end])
    return local_to_xy(cm, local)
