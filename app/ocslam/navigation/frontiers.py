"""Frontier detection (Yamauchi 1997): free cells next to unknown space, clustered.

A *frontier cell* is an observed cell that is more likely free than not (``0 <= v <= free_threshold``,
default 49: the edge of a SLAM grid is made of cells seen by one or two beams, whose occupancy is
still well above map_server's 25) with at least one 4-neighbour that is unknown (``-1``) or outside
the grid. Frontier cells are grouped into 8-connected clusters
(``scipy.ndimage.label``); clusters smaller than ``min_size_cells`` are dropped as noise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from app.ocslam.messages import OccupancyGrid
from app.ocslam.navigation.costmap import free_mask, unknown_mask

#: observed and more likely free than occupied
FRONTIER_FREE_THRESHOLD = 49

_EIGHT = np.ones((3, 3), dtype=bool)


@dataclass(slots=True)
class Frontier:
    """One frontier cluster.

    ``centroid_xy``: ``(2,)`` mean of its cell centres in the grid's frame (``map``); it may fall outside
    the cluster (curved frontiers). ``size``: number of cells. ``cells``: ``(size, 2)`` grid ``(row, col)``.
    """

    centroid_xy: NDArray[np.float64]
    size: int
    cells: NDArray[np.int64]

    def length_m(self, resolution: float) -> float:
        """Approximate frontier length: cell count × resolution."""
        return self.size * resolution


def frontier_mask(
    data: NDArray[np.integer], free_threshold: int = FRONTIER_FREE_THRESHOLD
) -> NDArray[np.bool_]:
    """``(H, W)`` True on free cells with an unknown (or off-grid) 4-neighbour."""
    unknown = np.pad(unknown_mask(data), 1, constant_values=True)
    near_unknown = unknown[:-2, 1:-1] | unknown[2:, 1:-1] | unknown[1:-1, :-2] | unknown[1:-1, 2:]
    return free_mask(data, free_threshold) & near_unknown


def label_frontiers(
    data: NDArray[np.integer], *, min_size_cells: int = 5, free_threshold: int = FRONTIER_FREE_THRESHOLD
) -> tuple[NDArray[np.int32], int]:
    """``(labels (H, W), n)``: 8-connected frontier clusters of at least ``min_size_cells`` cells,
    numbered ``1..n`` (0 elsewhere)."""
    mask = frontier_mask(data, free_threshold)
    labels, n = ndimage.label(mask, structure=_EIGHT)
    if n == 0:
        return labels.astype(np.int32), 0
    sizes = np.bincount(labels.ravel(), minlength=n + 1)
    keep = sizes >= max(1, min_size_cells)
    keep[0] = False
    new_id = np.zeros(n + 1, dtype=np.int32)
    new_id[keep] = np.arange(1, int(keep.sum()) + 1, dtype=np.int32)
    return new_id[labels], int(keep.sum())


def find_frontiers(
    grid: OccupancyGrid, *, min_size_cells: int = 5, free_threshold: int = FRONTIER_FREE_THRESHOLD
) -> list[Frontier]:
    """All frontier clusters of ``grid`` with at least ``min_size_cells`` cells, largest first."""
    data = np.asarray(grid.data)
    if data.ndim != 2 or data.size == 0:
        return []
    labels, n = label_frontiers(data, min_size_cells=min_size_cells, free_threshold=free_threshold)
    out = frontiers_from_labels(grid, labels, n)
    out.sort(key=lambda f: -f.size)
    return out


def frontiers_from_labels(
    grid: OccupancyGrid, labels: NDArray[np.int32], n: int, row0: int = 0, col0: int = 0
) -> list[Frontier]:
    """One :class:`Frontier` per label ``1..n`` of ``labels`` (a crop of ``grid`` starting at grid cell
    ``(row0, col0)``), in label order; ``cells`` are full-grid indices."""
    if n == 0:
        return []
    rows, cols = np.nonzero(labels)
    lab = labels[rows, cols]
    order = np.argsort(lab, kind="stable")
    rows, cols, lab = rows[order] + row0, cols[order] + col0, lab[order]
    sizes = np.bincount(lab, minlength=n + 1)[1:]
    res = grid.resolution
    local = np.stack([(cols + 0.5) * res, (rows + 0.5) * res], axis=1)
    xy = grid.origin.transform_points(local)
    cx = np.bincount(lab, weights=xy[:, 0], minlength=n + 1)[1:] / sizes
    cy = np.bincount(lab, weights=xy[:, 1], minlength=n + 1)[1:] / sizes
    splits = np.cumsum(sizes)[:-1]
    cell_groups = np.split(np.stack([rows, cols], axis=1).astype(np.int64), splits)
    return [
        Frontier(centroid_xy=np.array([cx[i], cy[i]]), size=int(sizes[i]), cells=cell_groups[i])
        for i in range(n)
    ]
