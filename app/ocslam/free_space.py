"""What the occupancy grid knows of places (improved mode): free space, known obstacles, and free floor seen between
two point sets. A :class:`GridSpace` is the ``known_free`` the footprints, the association and the collision rules
ask (``(N, 2)`` points in the grid's frame, ``map``)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from app.ocslam.classes import ClassPrior
from app.ocslam.footprint import nearest_distances
from app.ocslam.messages import OccupancyGrid

FloatArray = NDArray[np.float64]
#: ``(N, 2)`` points → ``(N,)`` True where the occupancy grid knows free space
FreeFn = Callable[[FloatArray], NDArray[np.bool_]]


#: occupancy below this (and known) is free space; at or above it the cell is not free
FREE_BELOW = 20


class GridSpace:
    """What the occupancy grid knows of ``(N, 2)`` points (grid frame): called, True where it knows free
    space (a :data:`~app.ocslam.footprint_estimate.FreeFn`); ``occupied``, ``None`` or a function True where
    it knows the cell is not free (occupancy ≥ :data:`FREE_BELOW`; the sweep's compact grids keep exactly this
    split), which footprints ask for known obstacles (principle 20; ``None`` when it is switched off)."""

    def __init__(self, grid: OccupancyGrid, occupied: bool = True, legs_free: bool = False) -> None:
        self._grid = grid
        self.occupied: Callable[[FloatArray], NDArray[np.bool_]] | None = self._not_free if occupied else None
        #: footprints may ask it whether the legs of an object completed from one support stand in known free
        #: space (``consciousness.legs_seen_free``)
        self.legs_free = legs_free

    def _values(self, points: FloatArray) -> NDArray[np.int64]:
        """``(N,)`` cell values, −1 (unknown) outside the grid."""
        g = self._grid
        cells = g.world_to_cell(points)
        r, c = cells[:, 0], cells[:, 1]
        inside = (r >= 0) & (r < g.height) & (c >= 0) & (c < g.width)
        if inside.all():
            return g.data[r, c].astype(np.int64)
        out = np.full(len(points), -1, dtype=np.int64)
        out[inside] = g.data[r[inside], c[inside]]
        return out

    def __call__(self, points: FloatArray) -> NDArray[np.bool_]:
        v = self._values(points)
        return (v >= 0) & (v < FREE_BELOW)

    def _not_free(self, points: FloatArray) -> NDArray[np.bool_]:
        return self._values(points) >= FREE_BELOW


def grid_free_fn(grid: OccupancyGrid | None, occupied: bool = True, legs_free: bool = False) -> GridSpace | None:
    """A :class:`GridSpace` of ``grid`` (``None`` without a usable grid); ``occupied``: whether footprints
    may ask it for known obstacles (``consciousness.hidden_behind_own_face``); ``legs_free``: whether for free
    space where legs would stand (``consciousness.legs_seen_free``)."""
    if grid is None or grid.data.size == 0 or not np.isfinite(grid.resolution) or grid.resolution <= 0:
        return None
    return GridSpace(grid, occupied, legs_free)


def gap_seen_free(a: FloatArray, b: FloatArray, pc: ClassPrior, known_free: FreeFn | None, step: float = 0.025) -> bool:
    """True if the map saw free floor between two point sets ``(N, 2)`` / ``(M, 2)`` (map frame) over more than
    one instance of the class can leave free inside itself: along the segment joining their closest points, a run
    of known-free samples (``step`` apart, 0.1 m from either end left out) longer than the class's
    :attr:`~app.ocslam.classes.ClassPrior.free_span` (its legs' span, an open frame's width; 0 for a solid
    cross-section) by 0.15 m. A solid body between two of its faces blocks the LIDAR. False without a grid."""
    if known_free is None or len(a) == 0 or len(b) == 0:
        return False
    if len(a) > len(b):
        a, b = b, a
    d = nearest_distances(a, b)
    i = int(np.argmin(d))
    p = a[i]
    q = b[int(np.argmin(np.hypot(b[:, 0] - p[0], b[:, 1] - p[1])))]
    allowed = pc.free_span + 0.15
    gap = float(d[i])
    if gap - 0.2 <= allowed:
        return False
    s = np.arange(0.1, gap - 0.1 + 1e-9, step)
    pts = p[None, :] + (q - p)[None, :] * (s / gap)[:, None]
    free = np.asarray(known_free(pts), dtype=bool)
    # longest run of consecutive free samples, in metres
    padded = np.concatenate([[0], free.astype(np.int8), [0]])
    edges = np.flatnonzero(np.diff(padded))
    runs = edges[1::2] - edges[0::2]
    return bool(len(runs)) and float(runs.max()) * step > allowed
