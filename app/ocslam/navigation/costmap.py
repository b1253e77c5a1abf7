"""Occupancy grid → planning cost map: obstacle inflation, clearance cost, traversability.

Conventions (the ROS ``nav_msgs/OccupancyGrid`` layout of :class:`~app.ocslam.messages.OccupancyGrid`):
``data[row, col]`` with ``-1`` unknown and ``0..100`` occupancy; cell ``(row, col)`` has its centre at
``origin ∘ ((col + 0.5)·res, (row + 0.5)·res)`` in the grid's frame (``map``). Cells are *occupied* at
``>= occupied_threshold`` (ROS map_server's 0.65), *free* at ``0 <= v <= free_threshold`` (0.25).

Inflation follows costmap_2d: a cell is blocked ("lethal") when its centre lies within the robot's
circumscribed radius of an occupied cell's centre, so a robot centred on any unblocked cell keeps that
radius from every obstacle cell centre. Around the blocked band a soft clearance cost decays linearly
to 1 over ``clearance_m`` so that paths prefer the middle of corridors and doorways.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from app.ocslam.messages import OccupancyGrid
from app.ocslam.se2 import Pose2

OCCUPIED_THRESHOLD = 65
FREE_THRESHOLD = 25

BoolGrid = NDArray[np.bool_]


def occupied_mask(data: NDArray[np.integer], occupied_threshold: int = OCCUPIED_THRESHOLD) -> BoolGrid:
    """``(H, W)`` True where the grid value is ``>= occupied_threshold``."""
    return np.asarray(data) >= occupied_threshold


def unknown_mask(data: NDArray[np.integer]) -> BoolGrid:
    """``(H, W)`` True where the grid value is negative (unknown)."""
    return np.asarray(data) < 0


def free_mask(data: NDArray[np.integer], free_threshold: int = FREE_THRESHOLD) -> BoolGrid:
    """``(H, W)`` True where ``0 <= value <= free_threshold``."""
    d = np.asarray(data)
    return (d >= 0) & (d <= free_threshold)


def obstacle_distance_m(obstacles: BoolGrid, resolution: float) -> NDArray[np.float32]:
    """``(H, W)`` Euclidean distance (m) from each cell centre to the nearest obstacle cell centre.

    ``inf`` everywhere when there is no obstacle. Exact and reproducible (OpenCV's precise L2 distance
    transform snapped to the integer squared distances).
    """
    obstacles = np.asarray(obstacles, dtype=bool)
    if not obstacles.any():
        return np.full(obstacles.shape, np.inf, dtype=np.float32)
    src = np.where(obstacles, 0, 255).astype(np.uint8)
    dist = cv2.distanceTransform(src, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    # the precise transform is exact up to float32 rounding that varies from run to run (threads, SIMD);
    # squared distances between cell centres are integers: snap to them so results are reproducible
    exact = np.sqrt(np.rint(dist.astype(np.float64) ** 2))
    return (exact * resolution).astype(np.float32)


def inflate(
    grid: OccupancyGrid,
    radius_m: float,
    *,
    occupied_threshold: int = OCCUPIED_THRESHOLD,
    unknown_is_obstacle: bool = False,
) -> BoolGrid:
    """``(H, W)`` bool: True where a robot of circumscribed radius ``radius_m`` centred on the cell
    would come within ``radius_m`` of an obstacle cell centre (obstacle cells themselves included).

    Obstacles are cells ``>= occupied_threshold``, plus unknown cells when ``unknown_is_obstacle``.
    """
    if not np.isfinite(radius_m) or radius_m < 0:
        raise ValueError(f"inflation radius must be finite and >= 0, got {radius_m!r}")
    obstacles = occupied_mask(grid.data, occupied_threshold)
    if unknown_is_obstacle:
        obstacles = obstacles | unknown_mask(grid.data)
    dist = obstacle_distance_m(obstacles, grid.resolution)
    # a small epsilon so that cells exactly at the radius count as blocked despite float rounding
    return dist <= radius_m + 1e-6 * grid.resolution


@dataclass(slots=True)
class CostMap:
    """A planning view of (a crop of) an occupancy grid.

    All arrays are ``(H, W)`` over the crop; crop cell ``(r, c)`` is grid cell ``(r + row0, c + col0)``.

    * ``blocked``: inflated obstacles (never entered, except the start's escape disk),
    * ``traversable``: cells a path may use,
    * ``cost``: multiplicative cell cost ``>= 1`` (clearance, unknown and escape penalties); the cost of a
      move is its length times the mean cost of its two cells,
    * ``clearance``: distance (m) from each cell centre to the nearest obstacle cell centre.
    """

    resolution: float
    origin: Pose2
    row0: int
    col0: int
    occupied: BoolGrid
    unknown: BoolGrid
    blocked: BoolGrid
    traversable: BoolGrid
    cost: NDArray[np.float64]
    clearance: NDArray[np.float32]

    @property
    def shape(self) -> tuple[int, int]:
        return self.traversable.shape

    def to_cells(self, points_xy: ArrayLike) -> NDArray[np.int64]:
        """``(N, 2)`` points in the map frame → ``(N, 2)`` crop ``(row, col)`` (may be out of bounds)."""
        local = self.to_local(points_xy)
        return np.floor(local[:, ::-1]).astype(np.int64)

    def to_local(self, points_xy: ArrayLike) -> NDArray[np.float64]:
        """``(N, 2)`` map-frame points → ``(N, 2)`` continuous crop coordinates ``(col, row)`` in cells
        (cell ``(r, c)`` spans ``[c, c+1) × [r, r+1)``)."""
        p = self.origin.inverse().transform_points(np.asarray(points_xy, dtype=np.float64).reshape(-1, 2))
        p /= self.resolution
        p[:, 0] -= self.col0
        p[:, 1] -= self.row0
        return p

    def to_xy(self, cells: ArrayLike) -> NDArray[np.float64]:
        """``(N, 2)`` crop ``(row, col)`` → ``(N, 2)`` cell centres in the map frame."""
        c = np.asarray(cells, dtype=np.float64).reshape(-1, 2)
        local = np.stack([(c[:, 1] + self.col0 + 0.5), (c[:, 0] + self.row0 + 0.5)], axis=1) * self.resolution
        return self.origin.transform_points(local)

    def in_bounds(self, cells: NDArray[np.int64]) -> NDArray[np.bool_]:
        h, w = self.shape
        return (cells[:, 0] >= 0) & (cells[:, 0] < h) & (cells[:, 1] >= 0) & (cells[:, 1] < w)


def _crop_box(
    data: NDArray[np.integer], keep_xy_cells: list[tuple[int, int]], margin: int
) -> tuple[int, int, int, int]:
    """Bounding box ``(r0, r1, c0, c1)`` (exclusive ends) of the known cells and the given cells."""
    h, w = data.shape
    known = data >= 0
    rows = np.flatnonzero(known.any(axis=1))
    cols = np.flatnonzero(known.any(axis=0))
    r_lo, r_hi, c_lo, c_hi = [], [], [], []
    if rows.size:
        r_lo.append(rows[0])
        r_hi.append(rows[-1])
        c_lo.append(cols[0])
        c_hi.append(cols[-1])
    for r, c in keep_xy_cells:
        r_lo.append(r)
        r_hi.append(r)
        c_lo.append(c)
        c_hi.append(c)
    if not r_lo:
        return 0, h, 0, w
    r0 = max(0, min(r_lo) - margin)
    r1 = min(h, max(r_hi) + margin + 1)
    c0 = max(0, min(c_lo) - margin)
    c1 = min(w, max(c_hi) + margin + 1)
    if r0 >= r1 or c0 >= c1:
        return 0, h, 0, w
    return int(r0), int(r1), int(c0), int(c1)


def build_costmap(
    grid: OccupancyGrid,
    robot_radius_m: float,
    *,
    start_xy: ArrayLike | None = None,
    keep_xy: ArrayLike | None = None,
    extra_obstacles_xy: ArrayLike | None = None,
    occupied_threshold: int = OCCUPIED_THRESHOLD,
    unknown_is_obstacle: bool = False,
    unknown_cost: float = 1.0,
    clearance_m: float = 0.3,
    clearance_weight: float = 3.0,
    escape_radius_m: float | None = None,
    escape_cost: float = 10.0,
    crop: bool = True,
    crop_margin_cells: int = 10,
) -> CostMap:
    """Build the :class:`CostMap` used by the planners.

    Args:
        grid: the SLAM grid (``map`` frame).
        robot_radius_m: circumscribed radius used for inflation.
        start_xy: ``(2,)`` robot position. When its cell is blocked (the robot is inside the inflation band,
            or even on an occupied cell because of map noise), the non-occupied cells within
            ``escape_radius_m`` (default ``radius + 2·res``) that are no closer to an obstacle than the
            start cell become traversable at ``escape_cost`` so the planner can leave without going
            deeper; the start cell itself is always made traversable.
        keep_xy: ``(N, 2)`` further points (e.g. the goal) that the crop must contain.
        extra_obstacles_xy: ``(M, 2)`` points whose cells count as occupied (virtual obstacles: places
            where the robot got stuck against something its LIDAR does not see, like glass).
        unknown_is_obstacle: unknown cells are obstacles (inflated, never entered); otherwise unknown cells
            are traversable with cost ``unknown_cost``.
        clearance_m, clearance_weight: soft cost ``1 + w·(1 − (d − radius)/clearance)`` between the
            blocked band and ``radius + clearance`` (``w = 0`` gives plain shortest paths).
        crop: plan on the bounding box of known cells (plus the start/keep points) with a margin.
    """
    if not np.isfinite(robot_radius_m) or robot_radius_m < 0:
        raise ValueError(f"robot radius must be finite and >= 0, got {robot_radius_m!r}")
    data = np.asarray(grid.data)
    if data.ndim != 2 or data.size == 0:
        raise ValueError(f"occupancy grid data must be a non-empty (H, W) array, got shape {data.shape}")
    res = float(grid.resolution)
    pts = []
    if start_xy is not None:
        pts.append(np.asarray(start_xy, dtype=np.float64).reshape(2))
    if keep_xy is not None:
        pts.extend(np.asarray(keep_xy, dtype=np.float64).reshape(-1, 2))
    keep_cells: list[tuple[int, int]] = []
    if pts:
        cells = grid.world_to_cell(np.asarray(pts))
        for r, c in cells:
            if 0 <= r < data.shape[0] and 0 <= c < data.shape[1]:
                keep_cells.append((int(r), int(c)))
    if crop:
        margin = crop_margin_cells + int(np.ceil((robot_radius_m + clearance_m) / res))
        r0, r1, c0, c1 = _crop_box(data, keep_cells, margin)
    else:
        r0, r1, c0, c1 = 0, data.shape[0], 0, data.shape[1]
    sub = data[r0:r1, c0:c1]

    occupied = occupied_mask(sub, occupied_threshold)
    if extra_obstacles_xy is not None and len(np.asarray(extra_obstacles_xy)):
        cells = grid.world_to_cell(np.asarray(extra_obstacles_xy, dtype=np.float64).reshape(-1, 2))
        cells -= np.array([r0, c0])
        ok = (
            (cells[:, 0] >= 0)
            & (cells[:, 0] < sub.shape[0])
            & (cells[:, 1] >= 0)
            & (cells[:, 1] < sub.shape[1])
        )
        occupied[cells[ok, 0], cells[ok, 1]] = True
    unknown = unknown_mask(sub)
    obstacles = occupied | unknown if unknown_is_obstacle else occupied
    dist = obstacle_distance_m(obstacles, res)
    blocked = dist <= robot_radius_m + 1e-6 * res
    traversable = ~blocked
    if unknown_is_obstacle:
        traversable &= ~unknown
    cost = np.ones(sub.shape, dtype=np.float64)
    if clearance_weight > 0 and clearance_m > 0:
        ramp = 1.0 - (dist.astype(np.float64) - robot_radius_m) / clearance_m
        cost += clearance_weight * np.clip(ramp, 0.0, 1.0)
    if not unknown_is_obstacle and unknown_cost != 1.0:
        cost[unknown] *= unknown_cost

    cm = CostMap(
        resolution=res,
        origin=grid.origin,
        row0=r0,
        col0=c0,
        occupied=occupied,
        unknown=unknown,
        blocked=blocked,
        traversable=traversable,
        cost=cost,
        clearance=dist,
    )
    if start_xy is not None:
        _add_escape(
            cm,
            np.asarray(start_xy, dtype=np.float64).reshape(2),
            robot_radius_m,
            escape_radius_m,
            escape_cost,
        )
    return cm


def _add_escape(
    cm: CostMap,
    start_xy: NDArray[np.float64],
    radius_m: float,
    escape_radius_m: float | None,
    escape_cost: float,
) -> None:
    """Let a start inside the inflation band (or on a noisy occupied cell) leave it at a high cost."""
    cell = cm.to_cells(start_xy[None])[0]
    if not cm.in_bounds(cell[None])[0] or cm.traversable[cell[0], cell[1]]:
        return
    if escape_radius_m is None:
        escape_radius_m = radius_m + 2.0 * cm.resolution
    k = int(np.ceil(escape_radius_m / cm.resolution)) + 1
    h, w = cm.shape
    r0, r1 = max(0, cell[0] - k), min(h, cell[0] + k + 1)
    c0, c1 = max(0, cell[1] - k), min(w, cell[1] + k + 1)
    rr, cc = np.mgrid[r0:r1, c0:c1]
    d = np.hypot(rr - cell[0], cc - cell[1]) * cm.resolution
    # the robot's own disk: the cells no closer to an obstacle than the start cell (the way out never
    # goes deeper into the band; unknown cells included: the robot stands there), as far as they are
    # connected to the start
    start_clearance = float(cm.clearance[cell[0], cell[1]])
    disk = (d <= escape_radius_m) & ~cm.occupied[r0:r1, c0:c1]
    disk &= cm.clearance[r0:r1, c0:c1] >= start_clearance - 1e-6
    disk[cell[0] - r0, cell[1] - c0] = True
    lab, _ = ndimage.label(disk, structure=np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], dtype=bool))
    win = (lab == lab[cell[0] - r0, cell[1] - c0]) & ~cm.traversable[r0:r1, c0:c1]
    cm.traversable[r0:r1, c0:c1] |= win
    cm.cost[r0:r1, c0:c1][win] = np.maximum(cm.cost[r0:r1, c0:c1][win], escape_cost)
    cm.traversable[cell[0], cell[1]] = True
    cm.cost[cell[0], cell[1]] = max(cm.cost[cell[0], cell[1]], escape_cost)


def segment_cells(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.int64]:
    """``(K, 2)`` crop cells ``(row, col)`` touched by the segment between continuous crop coordinates
    ``a`` and ``b`` (``(col, row)`` in cells, see :meth:`CostMap.to_local`).

    Conservative supercover: samples every quarter cell and adds both corner cells wherever consecutive
    samples change row and column at once, so no cell the segment passes through is missed.
    """
    n = max(2, int(np.ceil(np.hypot(*(b - a)) * 4.0)) + 1)
    t = np.linspace(0.0, 1.0, n)[:, None]
    p = a[None] + t * (b - a)[None]
    cells = np.floor(p[:, ::-1]).astype(np.int64)  # (row, col)
    prev, nxt = cells[:-1], cells[1:]
    diag = (prev[:, 0] != nxt[:, 0]) & (prev[:, 1] != nxt[:, 1])
    extra = [cells]
    if diag.any():
        extra.append(np.stack([prev[diag, 0], nxt[diag, 1]], axis=1))
        extra.append(np.stack([nxt[diag, 0], prev[diag, 1]], axis=1))
    return np.concatenate(extra, axis=0)
