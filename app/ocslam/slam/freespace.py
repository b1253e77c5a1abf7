"""Negative information for loop verification: does an aligned query contradict a submap's free space?

A correlative score only counts the query's points that land *near* the submap's surfaces; points that
land where the submap saw nothing do not lower it. In a floor of identical rooms a pose a few metres
along the corridor can therefore outscore the true one: it puts more of the query onto walls of the
old submap, while the rest of the query (the end of the corridor, a wall seen through a door) lands in
space the old submap saw *through*. :class:`FreeSpace` keeps that space: for a submap, in its anchor's
frame, the cells its keyframes' beams crossed (``free``) and the cells they ended in (``occupied``).
:func:`contradiction` scores an aligned query against it with two kinds of evidence:

- **points in free space**: a query return in a cell the submap's beams crossed, farther than
  ``tolerance_m`` from any submap return (a wall where the submap saw open floor);
- **rays through walls**: a query beam that crosses a submap return cell more than ``tolerance_m``
  before its own end, where the query has no return within ``tolerance_m`` (the query saw through a
  wall the submap saw; a beam grazing a wall both saw is not counted).

Both are fractions of the query's evidence that the submap *can judge* (points in cells it observed,
beams that cross an observed cell), so a query that only partly overlaps the submap is judged on the
overlap. At the true pose both stay at a few per cent (moving people, grazing beams, small pose
errors within the tolerance); an alias that slides a corridor by a room's width gets tens of per cent.

Grids are coarse (``resolution``, 0.1 m by default) and the submap's beams are cut at ``max_range_m``;
everything is vectorised with :func:`~app.ocslam.slam.raycast.cast_scan` / ``traverse``.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from app.ocslam.se2 import transform_points
from app.ocslam.slam.field import MatchField
from app.ocslam.slam.keyframes import KeyframeScan
from app.ocslam.slam.matcher import refine
from app.ocslam.slam.raycast import cast_scan, traverse


@dataclass
class FreeSpace:
    """A submap's observed space in its anchor's frame.

    ``origin``: ``(2,)`` map point of cell ``(0, 0)``'s corner; ``free``: ``(H, W)`` cells crossed by a beam and
    farther than the tolerance from every return; ``occupied``: ``(H, W)`` cells holding a return;
    ``near``: ``(H, W)`` cells within the tolerance of a return.
    """

    origin: NDArray[np.float64]
    resolution: float
    free: NDArray[np.bool_]
    occupied: NDArray[np.bool_]
    near: NDArray[np.bool_]
    tolerance_cells: int

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.free.shape[0]), int(self.free.shape[1]))

    def cells(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """``(N, 2)`` anchor-frame points → continuous cell coordinates ``(u_x, u_y)``."""
        return (np.asarray(points, np.float64).reshape(-1, 2) - self.origin) / self.resolution


def _cut(sensor: NDArray[np.float64], ends: NDArray[np.float64], hit: NDArray[np.bool_], max_range_m: float) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Beams longer than ``max_range_m`` are shortened to it and lose their return."""
    d = ends - sensor
    r = np.hypot(d[:, 0], d[:, 1])
    long = r > max_range_m
    if np.any(long):
        ends = ends.copy()
        ends[long] = sensor + d[long] * (max_range_m / r[long])[:, None]
        hit = hit & ~long
    return ends, hit


def build_free_space(
    rel: NDArray[np.float64],
    scans: list[KeyframeScan],
    resolution: float = 0.1,
    max_range_m: float = 15.0,
    tolerance_m: float = 0.15,
    stride: int = 2,
) -> FreeSpace | None:
    """Free and occupied cells of a submap's keyframes.

    Args:
        rel: ``(n, 3)`` ``T_anchor_kf`` of the submap's keyframes.
        scans: their :class:`KeyframeScan` (base frame).
        resolution: cell size (m).
        max_range_m: beams are cut here (the query only reaches ``loop_query_range_m`` anyway).
        tolerance_m: cells this close to a return are never called free (pose and range errors).
        stride: every ``stride``-th keyframe is cast (neighbouring keyframes see the same free space);
            every keyframe's returns are marked occupied.

    Returns None when the submap has no beams.
    """
    rel = np.asarray(rel, np.float64).reshape(-1, 3)
    sensors, ends_l, hits_l, pts_l = [], [], [], []
    for i, (T, sc) in enumerate(zip(rel, scans)):
        pts_l.append(transform_points(T, sc.points))
        if i % max(1, stride) and i != len(rel) - 1:
            continue
        s = transform_points(T, np.asarray(sc.sensor, np.float64).reshape(1, 2))[0]
        e, h = _cut(s, transform_points(T, sc.ends), np.asarray(sc.hit, bool), max_range_m)
        sensors.append(s)
        ends_l.append(e)
        hits_l.append(h)
    pts = np.vstack(pts_l) if pts_l else np.zeros((0, 2))
    if not ends_l and len(pts) == 0:
        return None
    allp = np.vstack([pts, *ends_l, np.array(sensors).reshape(-1, 2)])
    margin = 2.0 * tolerance_m + resolution
    origin = np.floor((allp.min(axis=0) - margin) / resolution) * resolution
    W, H = (np.ceil((allp.max(axis=0) + margin - origin) / resolution).astype(np.int64) + 1).tolist()
    free_n = np.zeros(H * W, np.int32)
    occ = np.zeros((H, W), bool)
    for s, e, h in zip(sensors, ends_l, hits_l):
        fr, fc, _, _ = cast_scan((s - origin) / resolution, (e - origin) / resolution, h)
        free_n += np.bincount(fr * W + fc, minlength=H * W).astype(np.int32)
    if len(pts):
        c = np.floor((pts - origin) / resolution).astype(np.int64)
        occ[c[:, 1], c[:, 0]] = True
    tol = int(np.ceil(tolerance_m / resolution))
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * tol + 1, 2 * tol + 1))
    near = cv2.dilate(occ.astype(np.uint8), kernel).astype(bool)
    free = (free_n.reshape(H, W) > 0) & ~near
    return FreeSpace(origin, float(resolution), free, occ, near, tol)


@dataclass
class Contradiction:
    """Evidence of an aligned query against a submap's :class:`FreeSpace`.

    ``points_free``: fraction of the query's judged points (in observed cells) lying in free space;
    ``rays_blocked``: fraction of the judged beams crossing a submap return well before their end;
    ``points_judged`` / ``rays_judged``: how many could be judged.
    """

    points_free: float
    rays_blocked: float
    points_judged: int
    rays_judged: int

    @property
    def worst(self) -> float:
        return max(self.points_free, self.rays_blocked)


def contradiction(
    fs: FreeSpace,
    T_anchor_query: NDArray[np.float64],
    points: NDArray[np.float64],
    sensor: NDArray[np.float64] | None = None,
    ends: NDArray[np.float64] | None = None,
    hit: NDArray[np.bool_] | None = None,
    max_range_m: float = 15.0,
) -> Contradiction:
    """Score a query at ``T_anchor_query`` ``(3,)`` against ``fs``.

    Args:
        points: ``(Q, 2)`` query returns in the query's frame (the loop query cloud).
        sensor, ends, hit: the query keyframe's own beams in its frame (``(2,)``, ``(B, 2)``, ``(B,)``)
            for the ray test; without them only the point test runs.
    """
    H, W = fs.shape
    c = np.floor(fs.cells(transform_points(T_anchor_query, np.asarray(points, np.float64).reshape(-1, 2)))).astype(np.int64)
    inside = (c[:, 0] >= 0) & (c[:, 0] < W) & (c[:, 1] >= 0) & (c[:, 1] < H)
    c = c[inside]
    # the query's own surfaces (with the tolerance): a submap wall there is one the query saw too
    q_occ = np.zeros((H, W), np.uint8)
    q_occ[c[:, 1], c[:, 0]] = 1
    k = 2 * fs.tolerance_cells + 1
    q_near = cv2.dilate(q_occ, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))).astype(bool)
    in_free = fs.free[c[:, 1], c[:, 0]]
    judged = in_free | fs.near[c[:, 1], c[:, 0]]
    n_p = int(judged.sum())
    p_free = float(in_free.sum()) / n_p if n_p else 0.0
    if sensor is None or ends is None or hit is None or len(ends) == 0:
        return Contradiction(p_free, 0.0, n_p, 0)
    s = transform_points(T_anchor_query, np.asarray(sensor, np.float64).reshape(1, 2))[0]
    e, h = _cut(s, transform_points(T_anchor_query, np.asarray(ends, np.float64).reshape(-1, 2)), np.asarray(hit, bool), max_range_m)
    # a beam is judged over its stretch that ends `tolerance` before its end (its own return's cell and
    # the submap's cells near it may legitimately hold a wall)
    d = e - s
    r = np.hypot(d[:, 0], d[:, 1])
    cut = (fs.tolerance_cells + 1) * fs.resolution
    ok = r > cut
    if not np.any(ok):
        return Contradiction(p_free, 0.0, n_p, 0)
    e2 = s + d[ok] * ((r[ok] - cut) / r[ok])[:, None]
    beam, rows, cols = traverse((s - fs.origin) / fs.resolution, (e2 - fs.origin) / fs.resolution)
    inside = (cols >= 0) & (cols < W) & (rows >= 0) & (rows < H)
    beam, rows, cols = beam[inside], rows[inside], cols[inside]
    B = int(ok.sum())
    blocked = np.zeros(B, bool)
    seen = np.zeros(B, bool)
    # a submap return the query's beam crossed, with no query return near it: the query saw through it
    blocked[beam[fs.occupied[rows, cols] & ~q_near[rows, cols]]] = True
    seen[beam[fs.free[rows, cols] | fs.occupied[rows, cols]]] = True
    n_r = int(seen.sum())
    r_blk = float((blocked & seen).sum()) / n_r if n_r else 0.0
    return Contradiction(p_free, r_blk, n_p, n_r)


def overlap_scores(fld: MatchField, fs: FreeSpace, points: NDArray[np.float64], poses: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Overlap-normalised likelihood of ``(Q, 2)`` query points at each of ``(T, 3)`` poses (anchor frame).

    Only points in cells the submap *observed* (``free`` or ``near``) count, and the score is their mean
    likelihood (a point in free space counts with its low likelihood). Unlike the correlative score, a
    pose gains nothing by moving more of the query into the submap's coverage. Returns ``(scores (T,),
    judged (T,))``.
    """
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    P = np.asarray(poses, np.float64).reshape(-1, 3)
    c, s = np.cos(P[:, 2]), np.sin(P[:, 2])
    q = np.empty((len(P), len(pts), 2))
    q[..., 0] = c[:, None] * pts[:, 0] - s[:, None] * pts[:, 1] + P[:, 0:1]
    q[..., 1] = s[:, None] * pts[:, 0] + c[:, None] * pts[:, 1] + P[:, 1:2]
    Hf, Wf = fld.shape
    u = np.floor((q - fld.origin_xy) / fld.resolution).astype(np.int64)
    inf_ = (u[..., 0] >= 0) & (u[..., 0] < Wf) & (u[..., 1] >= 0) & (u[..., 1] < Hf)
    L = np.where(inf_, fld.score[np.clip(u[..., 1], 0, Hf - 1), np.clip(u[..., 0], 0, Wf - 1)], 0.0)
    H, W = fs.shape
    v = np.floor((q - fs.origin) / fs.resolution).astype(np.int64)
    ins = (v[..., 0] >= 0) & (v[..., 0] < W) & (v[..., 1] >= 0) & (v[..., 1] < H)
    vr, vc = np.clip(v[..., 1], 0, H - 1), np.clip(v[..., 0], 0, W - 1)
    judged = ins & (fs.free[vr, vc] | fs.near[vr, vc])
    n = judged.sum(axis=1)
    sc = (L * judged).sum(axis=1) / np.maximum(n, 1)
    return sc.astype(np.float64), n.astype(np.int64)


def overlap_rival(
    fld: MatchField,
    fs: FreeSpace,
    points: NDArray[np.float64],
    pose: NDArray[np.float64],
    info: NDArray[np.float64],
    window_m: float,
    min_dist_m: float,
    ratio: float,
    scan: KeyframeScan | None = None,
    max_range_m: float = 15.0,
    extra_contradiction: float = 0.01,
    step_m: float = 0.05,
    min_overlap: float = 0.5,
    tries: int = 5,
) -> tuple[NDArray[np.float64] | None, float, float]:
    """A pose along the loop's principal translational directions that explains the overlap as well as
    ``pose`` does, without more contradiction.

    ``info`` ``(3, 3)`` is the loop's information in the query's frame; its eigenvectors, turned into
    the anchor's frame, are the directions searched, over ``±window_m`` at ``step_m`` beyond
    ``min_dist_m``, with the refined yaw. A rival must judge at least ``min_overlap`` as many points as
    ``pose``, reach ``ratio`` of its :func:`overlap_scores` score, and (with the query keyframe's
    ``scan``) contradict the submap with at most ``extra_contradiction`` of the judged points and
    beams (and 3) more than ``pose`` does (a slide that pushes the query's end wall behind the submap's, into space the submap never saw, is no
    rival: its beams cross that wall). The ``tries`` best lattice poses are examined in turn; the first
    rival is refined (:func:`~app.ocslam.slam.matcher.refine`). Returns ``(rival pose (3,) or None,
    score at pose, score at the rival)``.
    """
    pose = np.asarray(pose, np.float64).reshape(3)
    s0, n0 = overlap_scores(fld, fs, points, pose[None])
    best, nb = float(s0[0]), int(n0[0])
    if nb == 0:
        return None, best, 0.0
    _, V = np.linalg.eigh(np.asarray(info, np.float64)[:2, :2])
    c, s = np.cos(pose[2]), np.sin(pose[2])
    R = np.array([[c, -s], [s, c]])
    off = np.arange(-window_m, window_m + 0.5 * step_m, step_m)
    off = off[np.abs(off) > min_dist_m]
    if len(off) == 0:
        return None, best, 0.0
    cand = []
    for v in V.T:
        P = np.repeat(pose[None], len(off), axis=0)
        P[:, :2] += off[:, None] * (R @ v)[None]
        cand.append(P)
    P = np.vstack(cand)
    sc, n = overlap_scores(fld, fs, points, P)
    sc = np.where(n >= min_overlap * nb, sc, -1.0)

    def contra(x: NDArray[np.float64]) -> tuple[float, int]:
        """Contradicting points + beams at ``x``, and how many were judged."""
        if scan is None:
            return 0.0, 0
        c = contradiction(fs, x, points, scan.sensor, scan.ends, scan.hit, max_range_m)
        return c.points_free * c.points_judged + c.rays_blocked * c.rays_judged, c.points_judged + c.rays_judged

    base, n_base = contra(pose)
    tried: list[NDArray[np.float64]] = []
    for i in np.argsort(-sc):
        if sc[i] < ratio * best or len(tried) >= tries:
            break
        if any(np.hypot(*(P[i, :2] - t[:2])) < 0.2 for t in tried):
            continue
        tried.append(P[i])
        bad, n_bad = contra(P[i])
        if bad - base > max(3.0, extra_contradiction * max(n_bad, n_base)):
            continue
        ref = refine(fld, points, P[i], max_dist_m=2.0 * fld.resolution)
        x = ref.pose if np.hypot(*(ref.pose[:2] - pose[:2])) > min_dist_m else P[i]
        sr, nr = overlap_scores(fld, fs, points, x[None])
        if nr[0] < min_overlap * nb or sr[0] < sc[i]:
            x, sr = P[i], sc[i : i + 1]
        return x, best, float(sr[0])
    return None, best, 0.0


__all__ = ["FreeSpace", "Contradiction", "build_free_space", "contradiction", "overlap_scores", "overlap_rival"]
