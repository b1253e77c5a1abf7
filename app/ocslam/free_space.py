"""What the occupancy grid knows of places (improved mode): free space, known obstacles, and free floor seen between
two point sets. A :class:`GridSpace` is the ``known_free`` the footprints, the association and the collision rules
ask (``(N, 2)`` points in the grid's frame, ``map``); the footprints also ask it whether the floor they would extend
over, or where an object's other legs would stand, was seen free."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from app.ocslam.classes import ClassPrior
from app.ocslam.footprint import Footprint, linspace, nearest_distances
from app.ocslam.messages import OccupancyGrid

FloatArray = NDArray[np.float64]
#: ``(N, 2)`` points → ``(N,)`` True where the occupancy grid knows free space
FreeFn = Callable[[FloatArray], NDArray[np.bool_]]
#: A leg's place on the grid: its point and four neighbours 5 cm away, all known free for "seen free" (m).
LEG_PLACE = np.array([[0.0, 0.0], [0.05, 0.0], [-0.05, 0.0], [0.0, 0.05], [0.0, -0.05]])


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


def legs_seen_free(known_free: FreeFn, fp: Footprint, pts: FloatArray, leg: float) -> bool:
    """True if the grid knows free space at two of the footprint's corners that lie farther than ``leg`` from
    every point, where a legged object's other legs would stand (each corner inset by 8 cm, with its four
    neighbours 5 cm away: all five free)."""
    corners = Footprint(fp.center, fp.yaw, max(fp.size_x - 0.16, 0.0), max(fp.size_y - 0.16, 0.0)).corners
    far = nearest_distances(corners, pts) > leg
    n_far = int(np.count_nonzero(far))
    if n_far < 2:
        return False
    samples = (corners[far][:, None, :] + LEG_PLACE[None, :, :]).reshape(-1, 2)
    free = np.asarray(known_free(samples)).reshape(n_far, len(LEG_PLACE)).all(axis=1)
    return int(np.count_nonzero(free)) >= 2


def extension_free(
    known_free: FreeFn, axes: FloatArray, i: int, lo: FloatArray, hi: FloatArray, direction: int, length: float
) -> bool:
    """True if most of the band the rectangle would grow into along axis ``i`` (by ``length``, towards
    ``direction``) is known free."""
    if length <= 0.05 or direction == 0:
        return False
    j = 1 - i
    edge = hi[i] if direction > 0 else lo[i]
    a = edge + direction * linspace(0.1, max(length - 0.05, 0.1), 6)
    b = linspace(float(lo[j]), float(hi[j]), 5) if hi[j] - lo[j] > 0.05 else np.array([0.5 * (lo[j] + hi[j])])
    rect = np.empty((len(a) * len(b), 2))
    rect[:, i] = np.tile(a, len(b))  # the grid of (a, b), b-major (meshgrid's order)
    rect[:, j] = np.repeat(b, len(a))
    pts = rect @ axes  # rectangle coordinates → object frame
    free = known_free(pts)
    return int(np.count_nonzero(free)) / len(free) > 0.6


def far_legs_free(
    known_free: FreeFn, axes: FloatArray, i: int, lo: FloatArray, hi: FloatArray, direction: int, length: float
) -> bool:
    """For an object seen as legs: True if the grid knows free space where its far legs would stand, at both ends
    of the far edge of the rectangle grown along axis ``i`` (by ``length``, towards ``direction``), each inset by
    8 cm with its four neighbours 5 cm away (all five free). The floor between and under the legs is free anyway."""
    if length <= 0.05 or direction == 0:
        return False
    j = 1 - i
    edge = hi[i] if direction > 0 else lo[i]
    far = edge + direction * max(length - 0.08, 0.0)
    ends = (float(lo[j]) + 0.08, float(hi[j]) - 0.08) if hi[j] - lo[j] > 0.16 else (0.5 * float(lo[j] + hi[j]),) * 2
    rect = np.empty((2, 2))
    rect[:, i] = far
    rect[:, j] = ends
    pts = ((rect[:, None, :] + LEG_PLACE[None, :, :]).reshape(-1, 2)) @ axes  # rectangle coordinates → object frame
    return bool(np.asarray(known_free(pts)).reshape(2, len(LEG_PLACE)).all())
