"""The map a scan is matched against: a likelihood field plus nearest-point/normal lookups.

Built from ``(M, 2)`` map points (the returns of a few keyframes, in one frame ``F``):

- ``score``: ``(H, W)`` likelihood field ``exp(-d² / 2σ²)`` where ``d`` is the distance from the cell to the
  nearest occupied cell (OpenCV distance transform), computed on first use. The correlative matcher
  sums it over a scan.
- ``pyramid``: max-pooled copies of ``score`` for branch-and-bound (level ``h`` holds, at cell
  ``(i, j)``, the max of ``score`` over ``[i, i+2^h) × [j, j+2^h)``: an upper bound for any finer pose).
- ``nearest``: for every cell, the index of the nearest occupied cell's mean point ``points`` and the
  local surface normal ``normals`` (principal axis of the points in the 3×3 neighbourhood), so the
  continuous refinement uses exact sub-cell point-to-line distances.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray


@dataclass
class MatchField:
    """Matching structures in frame ``F``: see the module docstring. Grids have a zero border of 1 cell.

    ``score`` is computed on first use from ``dist_cells`` (the direct refinement of the front end never
    needs it, only the correlative search and the loop tests do).
    """

    resolution: float
    origin_xy: NDArray[np.float64]  # (2,) map position of cell (0, 0)'s corner
    dist_cells: NDArray[np.float32]  # (H, W) distance to the nearest occupied cell, in cells
    sigma_m: float  # width of the likelihood
    nearest: NDArray[np.int32]  # (H, W) index into points/normals, -1 where there is no point
    points: NDArray[np.float64]  # (P, 2) mean point of each occupied cell, frame F
    normals: NDArray[np.float64]  # (P, 2) unit normals
    linearity: NDArray[np.float64]  # (P,) 1 - λmin/λmax of the neighbourhood (1: a clean line)
    pyramid: list[NDArray[np.float32]] = field(default_factory=list)
    _score: NDArray[np.float32] | None = field(default=None, repr=False)

    @property
    def score(self) -> NDArray[np.float32]:
        """``(H, W)`` likelihood ``exp(-d² / 2σ²)``, zero on the border."""
        if self._score is None:
            d_m = self.dist_cells * np.float32(self.resolution)
            sc = np.exp(-0.5 * (d_m / np.float32(self.sigma_m)) ** 2).astype(np.float32)
            # zero border so clipped out-of-range lookups score nothing
            sc[0, :] = sc[-1, :] = 0.0
            sc[:, 0] = sc[:, -1] = 0.0
            self._score = sc
        return self._score

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.nearest.shape[0]), int(self.nearest.shape[1]))

    def to_cells(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """``(N, 2)`` points in ``F`` → continuous ``(u_x, u_y)`` cell coordinates."""
        return (points - self.origin_xy) / self.resolution

    def ensure_levels(self, levels: int) -> None:
        """Compute max-pooled pyramid levels ``0..levels``."""
        if not self.pyramid:
            self.pyramid.append(self.score)
        while len(self.pyramid) <= levels:
            h = len(self.pyramid)
            k = 2**h
            # anchor (0, 0): dst(i, j) = max over src[i : i+k, j : j+k]
            pooled = cv2.dilate(self.score, np.ones((k, k), np.uint8), anchor=(0, 0), borderType=cv2.BORDER_CONSTANT, borderValue=0)
            self.pyramid.append(np.asarray(pooled, np.float32))


def build_field(
    points: NDArray[np.float64],
    resolution: float,
    sigma_m: float,
    margin_m: float = 1.0,
    center: NDArray[np.float64] | None = None,
    half_size_m: float | None = None,
) -> MatchField | None:
    """Build a :class:`MatchField` from ``(M, 2)`` points in frame ``F``.

    Args:
        points: map points in ``F``.
        resolution: cell size (m).
        sigma_m: width of the Gaussian likelihood.
        margin_m: free border added around the points' bounding box.
        center, half_size_m: optionally crop the points to a square window around ``center``.

    Returns None when there are no points.
    """
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if center is not None and half_size_m is not None:
        pts = pts[np.all(np.abs(pts - center) <= half_size_m, axis=1)]
    if len(pts) == 0:
        return None
    res = float(resolution)
    margin_m = max(float(margin_m), 2.0 * res)
    lo = np.floor((pts.min(axis=0) - margin_m) / res) * res
    hi = pts.max(axis=0) + margin_m
    W = int(np.ceil((hi[0] - lo[0]) / res)) + 2
    H = int(np.ceil((hi[1] - lo[1]) / res)) + 2
    u = (pts - lo) / res
    col = u[:, 0].astype(np.int64)
    row = u[:, 1].astype(np.int64)
    flat = row * W + col
    n = H * W
    # per occupied cell: count and moments (coordinates relative to `lo` keep precision)
    cells, inv = np.unique(flat, return_inverse=True)
    P = len(cells)
    x, y = pts[:, 0] - lo[0], pts[:, 1] - lo[1]
    mom = np.zeros((P + 1, 6))  # row P: an empty cell, for missing neighbours
    for j, v in enumerate((None, x, y, x * x, x * y, y * y)):
        mom[:P, j] = np.bincount(inv, v, minlength=P)
    cnt = mom[:P, 0]
    mean = mom[:P, 1:3] / cnt[:, None]
    slot = np.full(n, P, np.int32)
    slot[cells] = np.arange(P, dtype=np.int32)
    # 3×3 neighbourhood sums (points are never in the outer two cells, so neighbours stay inside)
    nb = np.zeros((P, 6))
    for off in (-W - 1, -W, -W + 1, -1, 0, 1, W - 1, W, W + 1):
        nb += mom[slot[cells + off]]
    N = nb[:, 0]
    mx, my = nb[:, 1] / N, nb[:, 2] / N
    a = nb[:, 3] / N - mx * mx
    b = nb[:, 4] / N - mx * my
    c = nb[:, 5] / N - my * my
    phi = 0.5 * np.arctan2(2.0 * b, a - c)  # direction of the principal axis (the line)
    normals = np.stack([-np.sin(phi), np.cos(phi)], axis=1)
    tr = a + c
    disc = np.sqrt(np.maximum(0.25 * (a - c) ** 2 + b * b, 0.0))
    lmax = 0.5 * tr + disc
    lmin = 0.5 * tr - disc
    linearity = np.where(lmax > 1e-12, 1.0 - np.maximum(lmin, 0.0) / np.maximum(lmax, 1e-12), 0.0)
    linearity = np.where(N >= 3, linearity, 0.0)

    flat = np.full(n, 255, np.uint8)
    flat[cells] = 0
    mask = flat.reshape(H, W)
    dist, labels = cv2.distanceTransformWithLabels(mask, cv2.DIST_L2, cv2.DIST_MASK_5, labelType=cv2.DIST_LABEL_PIXEL)
    # labels number the zero pixels; map each label to the index of its occupied cell
    lab_of_cell = labels.reshape(-1)[cells]
    lut = np.full(int(labels.max()) + 1, -1, np.int32)
    lut[lab_of_cell] = np.arange(len(cells), dtype=np.int32)
    nearest = lut[labels]
    # zero border so clipped out-of-range lookups find no neighbour
    nearest[0, :] = nearest[-1, :] = -1
    nearest[:, 0] = nearest[:, -1] = -1
    return MatchField(
        resolution=res,
        origin_xy=lo,
        dist_cells=np.asarray(dist, np.float32),
        sigma_m=float(sigma_m),
        nearest=nearest,
        points=mean + lo,
        normals=normals,
        linearity=linearity,
    )
