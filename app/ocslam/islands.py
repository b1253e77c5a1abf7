"""Islands: clusters of the LIDAR points inside one bounding area (paper §2.5.3, Algorithm 1 line 3).

- :func:`islands_linkage` (improved): single-linkage clustering where the island threshold is the
  *largest gap inside an island* (the paper's "points separated by 10 cm"): two points are in the
  same island if a chain of points joins them with no step longer than the threshold. It equals the
  union of discs of radius ``threshold / 2`` (shapely's buffered multipoint), computed exactly with a
  KD-tree.
- :func:`islands_seed`: the original implementation's shapely ``MultiPoint.buffer(threshold)``
  union, whose islands join points up to ``2·threshold`` apart and whose boxes include the buffer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import shapely
from numpy.typing import NDArray
from scipy.spatial import cKDTree
from shapely.geometry import MultiPoint, Polygon

FloatArray = NDArray[np.float64]


@dataclass(eq=False)
class Island:
    """One island: ``points`` ``(K, 2)`` in the area's frame (``base_scan``), their indices in the scan's
    point array, and for seed islands the buffered polygon."""

    points: FloatArray
    indices: NDArray[np.int64]
    buffer_m: float = 0.05
    seed_polygon: Polygon | None = field(default=None, repr=False)
    #: extent of the whole scan cluster this island belongs to (it may continue outside its area);
    #: NaN when unknown
    full_extent: float = float("nan")
    #: why the fusion rejected it in its area (``None``: it passed), for the UI and diagnostics
    reason: str | None = None

    @cached_property
    def polygon(self) -> Polygon:
        """The island's outline: its points buffered by ``buffer_m`` (union), for drawing."""
        if self.seed_polygon is not None:
            return self.seed_polygon
        geom = MultiPoint(self.points).buffer(self.buffer_m, quad_segs=4)
        if isinstance(geom, Polygon):
            return geom
        return geom.convex_hull

    @property
    def centroid(self) -> FloatArray:
        return self.points.mean(axis=0)

    @property
    def bbox(self) -> tuple[float, float, float, float]:
        """``(minx, miny, maxx, maxy)``; seed islands include the buffer (as the original)."""
        if self.seed_polygon is not None:
            return tuple(float(v) for v in self.seed_polygon.bounds)  # type: ignore[return-value]
        lo, hi = self.points.min(axis=0), self.points.max(axis=0)
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])

    @property
    def bbox_center(self) -> FloatArray:
        x0, y0, x1, y1 = self.bbox
        return np.array([(x0 + x1) / 2.0, (y0 + y1) / 2.0])

    @property
    def extent(self) -> float:
        """Largest distance between two of its points (m); cheap upper bound via the bbox diagonal."""
        lo, hi = self.points.min(axis=0), self.points.max(axis=0)
        return float(np.hypot(*(hi - lo)))

    @property
    def physical_extent(self) -> float:
        """Extent of the physical cluster: ``full_extent`` if known, else the island's own."""
        return self.full_extent if math.isfinite(self.full_extent) else self.extent

    def __len__(self) -> int:
        return len(self.points)


def components(n: int, i: NDArray[np.int64], j: NDArray[np.int64]) -> tuple[int, NDArray[np.int64]]:
    """Connected components of the undirected graph on ``n`` nodes with edges ``(i[e], j[e])``.

    Returns ``(C, labels)``, ``labels`` ``(n,)`` numbered ``0..C-1`` in the order of each component's
    lowest node (the numbering of ``scipy.sparse.csgraph.connected_components``). Union-find by
    hooking roots to the lower root and pointer jumping, in numpy: a few vector passes instead of
    scipy's sparse-matrix construction and validation, which cost more than the search itself on the
    small graphs here (a scan's few hundred points). The edges between consecutive nodes (most of a
    scan's: its points come in scan order) first join their runs in one pass, so the chains they form
    need no pointer jumping.
    """
    nodes = np.arange(n, dtype=np.int64)
    i = np.asarray(i, dtype=np.int64).reshape(-1)
    j = np.asarray(j, dtype=np.int64).reshape(-1)
    if len(i) == 0:
        return n, nodes
    lo, hi = np.minimum(i, j), np.maximum(i, j)
    consecutive = hi - lo == 1
    joined = np.zeros(n, dtype=bool)  # joined[k]: an edge (k − 1, k)
    joined[hi[consecutive]] = True
    parent = np.maximum.accumulate(np.where(joined, 0, nodes))  # the first node of each run
    others = ~consecutive
    i, j = lo[others], hi[others]
    while len(i):
        ri, rj = parent[i], parent[j]
        differ = ri != rj
        if not differ.any():
            break
        ri, rj = ri[differ], rj[differ]
        i, j = i[differ], j[differ]
        np.minimum.at(parent, np.maximum(ri, rj), np.minimum(ri, rj))
        while True:  # pointer jumping: every node points at its root
            nxt = parent[parent]
            if (nxt == parent).all():
                break
            parent = nxt
    # every root is its component's lowest node (parents only ever decrease): number the roots in order
    roots = np.flatnonzero(parent == nodes)
    rank = np.empty(n, dtype=np.int64)
    rank[roots] = np.arange(len(roots))
    return len(roots), rank[parent]


def cluster_extents(
    points: FloatArray,
    gap_m: float,
    beam_index: NDArray[np.int64] | None = None,
    angle_increment: float = 0.0,
    n_beams: int = 0,
    max_incidence_deg: float = 10.0,
    sigma_m: float = 0.01,
    pairs_within_gap: NDArray[np.int64] | None = None,
) -> tuple[NDArray[np.int64], FloatArray]:
    """Clusters of a whole scan, for telling a small object from a piece of a larger surface.

    Points join when they are within ``gap_m`` (single linkage), or when they come from adjacent beams
    closer than the adaptive breakpoint distance ``r·sin(Δφ)/sin(λ − Δφ) + 3σ`` (Borges & Aldon), so a
    wall seen at a grazing angle — a chain of sparse points — stays one surface instead of a row of
    "legs". ``beam_index``: ``(N,)`` beam number of each point (scan order), ``n_beams`` the scan's
    size; ``pairs_within_gap``: :func:`close_pairs` of ``points`` at ``gap_m`` when the caller has them.
    Returns ``(N,)`` cluster labels and ``(C,)`` cluster extents (bounding-box diagonals).
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    n = len(pts)
    if n == 0:
        return np.full(0, -1, dtype=np.int64), np.zeros(0)
    # the edges, as their two ends (the components do not depend on their order)
    ends_i: list[NDArray[np.int64]] = []
    ends_j: list[NDArray[np.int64]] = []
    if n > 1:
        pairs = (np.asarray(pairs_within_gap, dtype=np.int64).reshape(-1, 2) if pairs_within_gap is not None
                 else close_pairs(pts, gap_m))  # the caller's close_pairs(points, gap_m), or ours
        ends_i.append(pairs[:, 0])
        ends_j.append(pairs[:, 1])
    if beam_index is not None and n > 1 and angle_increment > 0.0:
        bi = np.asarray(beam_index, dtype=np.int64)
        nxt = np.arange(1, n + 1)  # the next point in scan order (the last one's: the first)
        nxt[-1] = 0
        step = (bi[nxt] - bi) % max(n_beams, 1) if n_beams else bi[nxt] - bi
        adjacent = step == 1
        r = np.hypot(pts[:, 0], pts[:, 1])
        dphi = abs(angle_increment)
        lam = np.deg2rad(max_incidence_deg)
        dmax = r * np.sin(dphi) / np.sin(max(lam - dphi, 1e-3)) + 3.0 * sigma_m
        d = pts[nxt] - pts
        dist = np.hypot(d[:, 0], d[:, 1])
        ok = np.flatnonzero(adjacent & (dist <= np.maximum(dmax, gap_m)))
        ends_i.append(ok)
        ends_j.append(nxt[ok])
    if ends_i:
        n_clusters, labels = components(n, np.concatenate(ends_i), np.concatenate(ends_j))
    else:
        n_clusters, labels = n, np.arange(n, dtype=np.int64)
    # per-cluster bounds of x and y, as one flat array (element 2·c + axis)
    flat = np.empty(2 * n, dtype=np.int64)
    flat[0::2] = 2 * labels
    flat[1::2] = flat[0::2] + 1
    lo = np.full(2 * n_clusters, np.inf)
    hi = np.full(2 * n_clusters, -np.inf)
    np.minimum.at(lo, flat, pts.reshape(-1))
    np.maximum.at(hi, flat, pts.reshape(-1))
    span = hi - lo
    return labels, np.hypot(span[0::2], span[1::2])


def close_pairs(points: FloatArray, gap_m: float) -> NDArray[np.int64]:
    """``(P, 2)`` index pairs ``i < j`` of ``(N, 2)`` points within ``gap_m`` of each other (KD-tree)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(pts) < 2:
        return np.zeros((0, 2), dtype=np.int64)
    return np.asarray(cKDTree(pts).query_pairs(r=gap_m, output_type="ndarray"), dtype=np.int64).reshape(-1, 2)


def islands_linkage(
    points: FloatArray, indices: NDArray[np.int64], gap_m: float, scan_pairs: NDArray[np.int64] | None = None
) -> list[Island]:
    """Single-linkage islands: ``(K, 2)`` points → islands whose internal gaps are all ≤ ``gap_m``.

    Islands come out sorted by their first point index (scan order). ``scan_pairs``: the whole scan's
    :func:`close_pairs` at ``gap_m``, in the index space of ``indices`` (the pairs of a subset are those
    of the whole with both ends in it): given, no KD-tree is built per area.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    idx = np.asarray(indices, dtype=np.int64).reshape(-1)
    n = len(pts)
    if n == 0:
        return []
    if n == 1:
        return [Island(pts.copy(), idx.copy(), buffer_m=gap_m / 2.0)]
    if scan_pairs is not None and len(idx) and idx.min() >= 0:
        local = np.full(max(int(idx.max()), int(scan_pairs.max(initial=-1))) + 1, -1, dtype=np.int64)
        local[idx] = np.arange(n)
        sp = np.asarray(scan_pairs, dtype=np.int64).reshape(-1, 2)
        sel = sp[(local[sp[:, 0]] >= 0) & (local[sp[:, 1]] >= 0)]
        pairs = local[sel]
    else:
        pairs = close_pairs(pts, gap_m)
    n_comp, labels = components(n, pairs[:, 0], pairs[:, 1])
    if n_comp == 1:
        return [Island(pts.copy(), idx.copy(), buffer_m=gap_m / 2.0)]
    # the points grouped by island, each in its original order
    order = np.argsort(labels, kind="stable")
    ends = np.cumsum(np.bincount(labels, minlength=n_comp)).tolist()
    pts_by, idx_by = pts[order], idx[order]
    out = [Island(pts_by[a:b].copy(), idx_by[a:b].copy(), buffer_m=gap_m / 2.0) for a, b in zip([0, *ends[:-1]], ends)]
    if n_comp > 1 and not (idx[1:] >= idx[:-1]).all():
        # components come numbered by their lowest position in ``indices``: in scan order when it is sorted
        out.sort(key=lambda isl: int(isl.indices.min()))
    return out


def islands_seed(points: FloatArray, indices: NDArray[np.int64], buffer_m: float) -> list[Island]:
    """The original's islands: union of discs of radius ``buffer_m`` around every point (shapely).

    Each polygon of the union is an island; its points are those it contains.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    idx = np.asarray(indices, dtype=np.int64).reshape(-1)
    if len(pts) == 0:
        return []
    geom = MultiPoint(pts).buffer(buffer_m)
    polys = [geom] if isinstance(geom, Polygon) else list(getattr(geom, "geoms", []))
    out = []
    for poly in polys:
        m = shapely.intersects_xy(poly, pts[:, 0], pts[:, 1])
        if np.any(m):
            out.append(Island(pts[m], idx[m], buffer_m=buffer_m, seed_polygon=poly))
    return out
