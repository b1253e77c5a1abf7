"""Loop closure: match a new keyframe against older submaps with a global correlative search.

Keyframes are grouped into *submaps* of ``submap_keyframes`` consecutive keyframes (plus half a submap
of overlap). A finished submap's :class:`~app.ocslam.slam.field.MatchField` is built once, in the frame
of its first keyframe (its *anchor*), and cached; it is rebuilt only if an optimisation changed the
relative poses of its keyframes. For a new keyframe ``k``, the submaps that have a keyframe within
``loop_search_radius_m`` of ``k`` (and are old enough not to be part of the local map) are searched with
branch and bound over a window of ``±loop_window_xy_m × ±loop_window_yaw_rad`` that grows by
``loop_window_growth`` per metre travelled since the last accepted closure (up to
``loop_window_max_xy_m``/``loop_window_max_yaw_rad``), as the drift it must absorb does; the candidate
radius grows with it. The query is the keyframe's
local cloud (its scan and its predecessors', voxel-downsampled), which is more distinctive than one scan.

Acceptance (strict): the discrete score must reach ``loop_min_score``, the continuous refinement must
keep at least ``loop_min_inliers`` of the query points within 5 cm of the submap's surfaces, and the
refinement must not wander more than two cells from the discrete optimum. Each closure carries the
information of its refinement (:mod:`.information`, in the keyframe's frame: loose along a corridor).
Local uniqueness: if another pose of the search window farther than ``loop_ambiguity_m`` scores at
least ``loop_ambiguity_ratio`` of the best (:func:`~app.ocslam.slam.matcher.competitor`: doors at a
regular spacing, a featureless corridor), the closure keeps no information along the direction to
that competitor (:func:`~app.ocslam.slam.information.strip_direction`). Accepted here means *candidate*: :mod:`.verify` confirms it before the pose graph gets the edge (with a
robust Cauchy kernel).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from app.ocslam.config import SlamConfig
from app.ocslam.se2 import between, transform_points, wrap_angle
from app.ocslam.slam.field import MatchField, build_field
from app.ocslam.slam.freespace import Contradiction, FreeSpace, build_free_space, contradiction, overlap_rival
from app.ocslam.slam.information import scan_information, strip_direction
from app.ocslam.slam.keyframes import Keyframes
from app.ocslam.slam.matcher import competitor, correlative_search, line_hessian, refine


@dataclass
class LoopClosure:
    anchor: int  # keyframe index of the submap's anchor (edge from `anchor` to `keyframe`)
    keyframe: int
    measurement: NDArray[np.float64]  # (3,) T_anchor_keyframe
    score: float
    inlier_fraction: float
    info: NDArray[np.float64] | None = None  # (3, 3) information of the match in the keyframe's frame
    contradiction: Contradiction | None = None  # the aligned query against the submap's free space


@dataclass
class _Submap:
    first: int
    last: int  # exclusive
    rel: NDArray[np.float64]  # (n, 3) T_anchor_kf used to build the field
    field: MatchField | None
    free: FreeSpace | None = None  # built on the first candidate against this submap (see .freespace)


def voxel_downsample(points: NDArray[np.float64], voxel: float) -> NDArray[np.float64]:
    """One point (the mean) per ``voxel``-sized cell of ``(N, 2)`` points."""
    if len(points) == 0:
        return points
    key = np.floor(points / voxel).astype(np.int64)
    _, inv, cnt = np.unique(key[:, 0] * 1_000_003 + key[:, 1], return_inverse=True, return_counts=True)
    out = np.zeros((len(cnt), 2))
    np.add.at(out, inv, points)
    return out / cnt[:, None]


class LoopCloser:
    """Finds loop closures of new keyframes against cached older submaps (see the module docstring)."""

    def __init__(self, cfg: SlamConfig) -> None:
        self.cfg = cfg
        self.submaps: dict[int, _Submap] = {}
        self.searches = 0
        self.accepted = 0
        self.ambiguous = 0  # candidates with a competitor (information stripped along it)
        self.ambiguous_overlap = 0  # candidates stripped by the overlap-normalised test (.freespace.overlap_rival)
        self.travel_since_loop = 0.0  # m travelled since the last accepted loop closure
        self.log: list[tuple] = []

    def window(self) -> tuple[float, float]:
        """Search window half-sizes ``(xy m, yaw rad)``: they grow with the distance travelled since the
        last accepted loop closure, as the drift they must absorb does."""
        cfg = self.cfg
        t = self.travel_since_loop
        xy = min(cfg.loop_window_xy_m + cfg.loop_window_growth * t, max(cfg.loop_window_max_xy_m, cfg.loop_window_xy_m))
        yaw = min(cfg.loop_window_yaw_rad + cfg.loop_window_growth * t / 5.0, max(cfg.loop_window_max_yaw_rad, cfg.loop_window_yaw_rad))
        return xy, yaw

    def _submap_range(self, s: int) -> tuple[int, int]:
        S = self.cfg.submap_keyframes
        return s * S, (s + 1) * S + S // 2

    def submap(self, kfs: Keyframes, s: int) -> _Submap:
        first, last = self._submap_range(s)
        poses = kfs.poses.data
        rel = between(poses[first], poses[first:last])
        sm = self.submaps.get(s)
        if sm is not None:
            d = rel - sm.rel
            d[:, 2] = wrap_angle(d[:, 2])
            if np.max(np.abs(d[:, :2])) < 0.5 * self.cfg.match_resolution_m and np.max(np.abs(d[:, 2])) < 0.005:
                return sm
        pts = [transform_points(rel[i], kfs.scans[first + i].points) for i in range(last - first)]
        fld = build_field(
            np.vstack(pts) if pts else np.zeros((0, 2)),
            self.cfg.match_resolution_m,
            self.cfg.match_sigma_m,
            margin_m=0.5,
        )
        sm = _Submap(first, last, rel, fld)
        self.submaps[s] = sm
        return sm

    def free_space(self, kfs: Keyframes, sm: _Submap) -> FreeSpace | None:
        """The submap's :class:`~.freespace.FreeSpace` (built once per field, lazily)."""
        if sm.free is None:
            sm.free = build_free_space(sm.rel, kfs.scans[sm.first : sm.last], max_range_m=1.5 * self.cfg.loop_query_range_m)
        return sm.free

    def query_cloud(self, kfs: Keyframes, k: int) -> NDArray[np.float64]:
        """``(Q, 2)`` points of keyframe ``k`` and its predecessors in ``k``'s frame, downsampled."""
        n = self.cfg.loop_query_keyframes
        poses = kfs.poses.data
        first = max(0, k - n + 1)
        rel = between(poses[k], poses[first : k + 1])
        pts = np.vstack([transform_points(rel[i], kfs.scans[first + i].points) for i in range(k + 1 - first)])
        pts = pts[np.hypot(pts[:, 0], pts[:, 1]) <= self.cfg.loop_query_range_m]
        pts = voxel_downsample(pts, 2.0 * self.cfg.match_resolution_m)
        if len(pts) > self.cfg.loop_query_max_points:
            sel = np.linspace(0, len(pts) - 1, self.cfg.loop_query_max_points).astype(np.int64)
            pts = pts[sel]
        return pts

    def candidates(self, kfs: Keyframes, k: int, radius: float) -> list[int]:
        """Submap ids with a keyframe within ``radius`` of keyframe ``k``, nearest first."""
        cfg = self.cfg
        S = cfg.submap_keyframes
        # a submap is eligible once it is complete and older than the local map window
        newest = k - cfg.local_map_keyframes - cfg.loop_min_gap_keyframes
        n_sub = max(0, (newest - S // 2) // S)
        if n_sub <= 0:
            return []
        last_kf = self._submap_range(n_sub - 1)[1]
        poses = kfs.poses.data
        d = np.hypot(*(poses[:last_kf, :2] - poses[k, :2]).T)
        sid = np.arange(last_kf) // S
        sid = np.minimum(sid, n_sub - 1)
        best = np.full(n_sub, np.inf)
        np.minimum.at(best, sid, d)
        ids = np.flatnonzero(best < radius)
        ids = ids[np.argsort(best[ids])]
        return [int(s) for s in ids[: cfg.loop_max_candidates]]

    def search(self, kfs: Keyframes, k: int) -> list[LoopClosure]:
        """Try to close loops from keyframe ``k``; returns the accepted closures."""
        cfg = self.cfg
        if k > 0:
            p = kfs.poses.data
            self.travel_since_loop += float(np.hypot(*(p[k, :2] - p[k - 1, :2])))
        win_xy, win_yaw = self.window()
        cands = self.candidates(kfs, k, cfg.loop_search_radius_m + win_xy - cfg.loop_window_xy_m)
        if not cands:
            return []
        query = self.query_cloud(kfs, k)
        if len(query) < cfg.min_points:
            return []
        poses = kfs.poses.data
        out: list[LoopClosure] = []
        for s in cands:
            sm = self.submap(kfs, s)
            if sm.field is None:
                continue
            self.searches += 1
            center = between(poses[sm.first], poses[k])
            res = correlative_search(
                sm.field, query, center, win_xy, win_yaw, cfg.match_yaw_step_rad, cfg.loop_min_score
            )
            if res is None:
                continue
            ref = refine(
                sm.field,
                query,
                res.pose,
                max_dist_m=2.0 * cfg.match_resolution_m,
                robust_m=cfg.match_robust_m,
                point_weight=cfg.match_point_weight,
            )
            moved = np.hypot(*(ref.pose[:2] - res.pose[:2]))
            ev = np.linalg.eigvalsh(ref.hessian[:2, :2])
            constraint = float(ev[0] / ev[1]) if ev[1] > 0 else 0.0
            self.log.append((k, s, res.score, ref.inlier_fraction, float(moved), constraint))
            if ref.inlier_fraction < cfg.loop_min_inliers or moved > 2.0 * cfg.match_resolution_m:
                continue
            if constraint < cfg.loop_min_constraint:
                continue
            self.accepted += 1
            fs = self.free_space(kfs, sm)
            contra = None
            if fs is not None:
                q = kfs.scans[k]
                contra = contradiction(fs, ref.pose, query, q.sensor, q.ends, q.hit, max_range_m=1.5 * cfg.loop_query_range_m)
            info = scan_information(
                line_hessian(ref), float(ref.pose[2]), cfg.match_info_point_sigma_m, cfg.loop_sigma_xy_m, cfg.loop_sigma_yaw_rad, cfg.match_info_floor
            )
            if cfg.loop_ambiguity_ratio <= 1.0:
                rival = competitor(
                    sm.field, query, center, win_xy, win_yaw, cfg.match_yaw_step_rad, res.pose, cfg.loop_ambiguity_m,
                    max(cfg.loop_min_score, cfg.loop_ambiguity_ratio * res.score),
                )
                if rival is not None:
                    # another place looks as good: trust the match across that direction and in heading only
                    self.ambiguous += 1
                    d = rival.pose[:2] - res.pose[:2]
                    c, s_ = np.cos(ref.pose[2]), np.sin(ref.pose[2])
                    d_body = np.array([c * d[0] + s_ * d[1], -s_ * d[0] + c * d[1]])
                    info = strip_direction(info, d_body, cfg.loop_sigma_xy_m, cfg.loop_sigma_yaw_rad, cfg.match_info_floor)
            if fs is not None and cfg.loop_ambiguity_ratio <= 1.0:
                # the same test with the overlap-normalised score: along a featureless stretch a pose
                # that moves more of the query into the submap's coverage outscores the true one in
                # the correlative score, not here
                alt, s_best, s_alt = overlap_rival(
                    sm.field, fs, query, ref.pose, info, win_xy, cfg.loop_ambiguity_m, cfg.loop_ambiguity_ratio, kfs.scans[k], 1.5 * cfg.loop_query_range_m
                )
                if alt is not None:
                    self.ambiguous_overlap += 1
                    d = alt[:2] - ref.pose[:2]
                    c, s_ = np.cos(ref.pose[2]), np.sin(ref.pose[2])
                    d_body = np.array([c * d[0] + s_ * d[1], -s_ * d[0] + c * d[1]])
                    info = strip_direction(info, d_body, cfg.loop_sigma_xy_m, cfg.loop_sigma_yaw_rad, cfg.match_info_floor)
            out.append(LoopClosure(sm.first, k, ref.pose, res.score, ref.inlier_fraction, info, contra))
        return out

    def forget(self) -> None:
        self.submaps.clear()


__all__ = ["LoopCloser", "LoopClosure", "voxel_downsample"]
