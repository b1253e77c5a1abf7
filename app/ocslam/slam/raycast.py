"""Vectorised ray casting on a regular grid (exact cell traversal, no per-beam Python loop).

All coordinates here are *continuous cell coordinates* ``u = (p_xy - grid_origin_xy) / resolution``:
cell ``(row, col)`` covers ``col <= u_x < col + 1`` and ``row <= u_y < row + 1``.

A segment from ``start`` to ``end`` passes through the start cell, then one new cell each time it
crosses a vertical (``u_x`` integer) or horizontal (``u_y`` integer) grid line. We enumerate those
crossings for every beam at once (ragged arrays built with ``np.repeat``), so the traversed set is
exact (the cells the open segment touches), with no sampling step to tune.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def _ragged_arange(counts: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """For counts ``(B,)`` return (beam index, k) with k = 1..counts[b] for every beam, concatenated."""
    total = int(counts.sum())
    if total == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    beam = np.repeat(np.arange(len(counts)), counts)
    starts = np.cumsum(counts) - counts
    k = np.arange(total) - np.repeat(starts, counts) + 1
    return beam, k


def traverse(start: NDArray[np.float64], ends: NDArray[np.float64]) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Cells crossed by segments from one ``start`` (2,) to each of ``ends`` (B, 2), in cell coordinates.

    Returns ``(beam, row, col)`` arrays: every cell each segment passes through, the start cell and the
    end cell included, each cell once per beam (several beams may share a cell).
    """
    start = np.asarray(start, np.float64).reshape(2)
    ends = np.asarray(ends, np.float64).reshape(-1, 2)
    B = len(ends)
    c0 = np.floor(start).astype(np.int64)
    c1 = np.floor(ends).astype(np.int64)
    d = ends - start
    out_b = [np.arange(B)]
    out_r = [np.full(B, c0[1])]
    out_c = [np.full(B, c0[0])]
    for axis in (0, 1):  # 0: vertical lines (x), 1: horizontal lines (y)
        n = np.abs(c1[:, axis] - c0[axis])
        beam, k = _ragged_arange(n)
        if len(beam) == 0:
            continue
        sgn = np.sign(d[beam, axis]).astype(np.int64)
        # line crossed: for +dir, c0+k; for -dir, c0-k+1. The cell entered: c0+k or c0-k.
        line = np.where(sgn > 0, c0[axis] + k, c0[axis] - k + 1)
        entered = c0[axis] + sgn * k
        t = (line - start[axis]) / d[beam, axis]
        other = 1 - axis
        # the other coordinate just after the crossing (so a corner crossing enters the diagonal cell)
        o = np.floor(start[other] + (t + 1e-9) * d[beam, other]).astype(np.int64)
        # keep the "other" coordinate inside the segment's own range (guards rounding at lattice corners)
        lo = np.minimum(c0[other], c1[beam, other])
        hi = np.maximum(c0[other], c1[beam, other])
        o = np.clip(o, lo, hi)
        out_b.append(beam)
        if axis == 0:
            out_c.append(entered)
            out_r.append(o)
        else:
            out_r.append(entered)
            out_c.append(o)
    return np.concatenate(out_b), np.concatenate(out_r), np.concatenate(out_c)


def cast_scan(
    start: NDArray[np.float64], ends: NDArray[np.float64], hit: NDArray[np.bool_]
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Free and occupied cells of one scan in cell coordinates.

    Args:
        start: ``(2,)`` sensor origin.
        ends: ``(B, 2)`` beam end points: the return for ``hit`` beams, the clearing limit for the others.
        hit: ``(B,)`` True where the beam ended on an obstacle (its end cell is marked occupied).

    Returns:
        ``(free_rows, free_cols, hit_rows, hit_cols)``. Free cells are every cell traversed by a beam
        except a hit beam's end cell; beams without a return mark nothing. A cell that is the end cell of
        any hit beam of this scan is never reported free for this scan (hits take precedence).
        Free cells may repeat (one entry per beam through the cell).
    """
    ends = np.asarray(ends, np.float64).reshape(-1, 2)
    hit = np.asarray(hit, bool).reshape(-1)
    beam, rows, cols = traverse(start, ends)
    end_cells = np.floor(ends).astype(np.int64)
    hr, hc = end_cells[hit, 1], end_cells[hit, 0]
    free = np.ones(len(beam), bool)
    if len(hr):
        # drop the end cell of each hit beam, then any cell that some hit beam ends in
        is_end = hit[beam] & (rows == end_cells[beam, 1]) & (cols == end_cells[beam, 0])
        free &= ~is_end
        lo_r, lo_c = min(rows.min(), hr.min()), min(cols.min(), hc.min())
        w = max(cols.max(), hc.max()) - lo_c + 1
        key = (rows - lo_r) * w + (cols - lo_c)
        hkey = (hr - lo_r) * w + (hc - lo_c)
        free &= ~np.isin(key, hkey)
    return rows[free], cols[free], hr, hc
