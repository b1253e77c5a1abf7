"""What a tracked object has accumulated from its observations (improved mode).

Every observation of an object adds:

- its island points (voxel-downsampled; ``hits`` counts the points a voxel merged, ``frames`` the views that
  added to it),
- the *bisector ray* of its box (apex and direction on the floor plane): the object's centre lies near
  it (the paper's assumption 2); rays of boxes cut by the image border only count as viewpoints,
- for objects the LIDAR cannot see, a ground-plane centre (rolling average, the paper's 90 % weight).

All of it is stored in the object frame (``map``) tagged with the SLAM keyframe it was seen from, so a
loop-closure correction moves every piece rigidly with its keyframe (:meth:`ObjectEvidence.transform`).
The footprint estimated from it is :func:`app.ocslam.footprint_estimate.estimate_footprint`.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from app.ocslam.se2 import Pose2

FloatArray = NDArray[np.float64]
#: The keyframe tag of evidence seen without a SLAM keyframe.
NO_KEYFRAME = -1


def _appended(a: NDArray, value: object) -> NDArray:
    """A copy of ``a`` ``(N, ...)`` with one more row ``value`` (``np.append``/``np.vstack`` without their
    overhead)."""
    out = np.empty((len(a) + 1,) + a.shape[1:], dtype=a.dtype)
    out[:-1] = a
    out[-1] = value
    return out


def _unique_inverse(keys: NDArray[np.int64]) -> tuple[NDArray[np.intp], int]:
    """``(inverse, count)`` of ``np.unique(keys, return_inverse=True)`` for a non-empty ``(N,)`` array:
    each key's rank among the distinct keys (ascending), the same sort and ranks without the wrapper's
    overhead."""
    perm = keys.argsort()
    srt = keys[perm]
    new = np.empty(len(srt), dtype=bool)
    new[0] = True
    np.not_equal(srt[1:], srt[:-1], out=new[1:])
    rank = np.cumsum(new) - 1
    inv = np.empty(len(srt), dtype=np.intp)
    inv[perm] = rank
    return inv, int(rank[-1]) + 1


@lru_cache(maxsize=8)
def _lower_triangle(n: int) -> NDArray[np.bool_]:
    """``(n, n)`` mask of the diagonal and below (read-only, cached: the ray count is always
    ``max_rays + 1`` here)."""
    m = np.tril(np.ones((n, n), dtype=bool))
    m.setflags(write=False)
    return m


def _nan_list(v: FloatArray) -> list[float | None]:
    """``(N,)`` floats as JSON: NaN (unknown) as ``None``."""
    return [None if not np.isfinite(x) else float(x) for x in v]


def _nan_array(items: list | None, n: int) -> FloatArray:
    """:func:`_nan_list`'s inverse; ``n`` NaNs (all unknown) when ``items`` is absent (an older state)."""
    if items is None:
        return np.full(n, np.nan)
    return np.array([np.nan if x is None else float(x) for x in items], dtype=np.float64)


class ObjectEvidence:
    """What one tracked object has accumulated: points, bisector rays and ground-plane centres.

    Arrays are in the object frame (``map``); each entry carries the keyframe it was seen from.
    """

    def __init__(self, voxel_m: float = 0.03, max_points: int = 800, max_rays: int = 48) -> None:
        self.voxel_m = voxel_m
        self.max_points = max_points
        self.max_rays = max_rays
        self.points = np.zeros((0, 2))
        self.hits = np.zeros(0, dtype=np.int64)
        #: per voxel: the views (calls of :meth:`add_points`) that added a point to it; a view counts once however many
        #: of its points fell in the voxel (a near leg gives several a frame, a far one one or none)
        self.frames = np.zeros(0, dtype=np.int64)
        self.point_kf = np.zeros(0, dtype=np.int64)
        #: per voxel: frames in which the LIDAR saw it inside the image but outside the object's own box
        #: (:mod:`app.ocslam.outside`); ``outside_ratio`` (``consciousness.outside_ratio``, 0: off) decides
        #: which voxels still shape the object (:meth:`trusted`)
        self.outside = np.zeros(0, dtype=np.int64)
        self.outside_ratio = 0.0
        #: ``consciousness.ray_centre_sigma_m`` (0: off): where the bisector rays fix the centre this well,
        #: voxels farther from it than the object can reach do not shape it (:func:`app.ocslam.ray_centre.ray_centre`)
        self.ray_centre_sigma = 0.0
        #: ``consciousness.ray_centre_behind_surface``: a crossing on the viewers' side of the points fixes nothing
        self.ray_centre_behind_surface = True
        #: ``consciousness.box_width_cap`` (0: off): across the line of sight the object spans at most this
        #: many times its boxes' apparent width (:func:`app.ocslam.footprint_estimate.estimate_footprint`)
        self.box_width_cap = 0.0
        #: ``consciousness.far_face``: an open frame's face returned well beyond where its boxes' bottom edges put its
        #: base is its far side (:func:`app.ocslam.footprint_estimate.estimate_footprint`)
        self.far_face = False
        #: ``consciousness.legs_extend``: an object seen as legs is completed over free floor unless its far legs'
        #: places are seen free (the floor under a table is free)
        self.legs_extend = False
        #: ``consciousness.stray_by_views``: the stray filter counts a voxel's views (``frames``), not its points (``hits``)
        self.stray_by_views = True
        self.ray_origin = np.zeros((0, 2))
        self.ray_dir = np.zeros((0, 2))
        self.ray_weight = np.zeros(0)
        self.ray_kf = np.zeros(0, dtype=np.int64)
        self.ray_app = np.zeros(0)  # apparent width seen along each ray (m), NaN if unknown
        self.ray_open = np.zeros(0, dtype=np.int64)  # +1/-1: box cut by the image's left/right border
        self.ray_base = np.zeros(0)  # the range of the box's bottom edge on the floor from the origin (m), NaN if unknown
        self.gp_center: FloatArray | None = None
        self.gp_kf: int = NO_KEYFRAME
        #: legged classes: observations as one small island on the box's centre line vs. off it / several legs
        self.support_obs = 0
        self.corner_obs = 0
        #: observations with points, and those whose points were all leg-sized islands (legged classes)
        self.observations = 0
        self.leg_obs = 0
        #: bumped when ``points`` is changed in place (a correction); a new ``points`` array is a change too
        self.points_revision = 0
        #: what :func:`app.ocslam.footprint_estimate.estimate_footprint` derived from these points (its cache), and from
        #: those of them within reach of the rays' crossing (keyed by the cached points and the chosen voxels)
        self.shape_cache: tuple | None = None
        self.ray_shape_cache: tuple | None = None

    # -- accumulation ----------------------------------------------------------------------------
    @property
    def has_points(self) -> bool:
        return len(self.points) > 0

    def add_points(
        self, points: FloatArray, kf: int = NO_KEYFRAME, outside: NDArray[np.int64] | None = None,
        frames: NDArray[np.int64] | None = None,
    ) -> None:
        """Add ``(N, 2)`` points (object frame), merging them into voxels of ``voxel_m``; ``outside``
        ``(N,)`` their counts of views outside the object's box (:meth:`absorb`; default none); ``frames`` ``(N,)``
        the views each point carries (:meth:`absorb`; default: one view, counted once in each voxel it reaches)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        fin = np.isfinite(p)
        ok = fin[:, 0] & fin[:, 1]
        out_new = np.zeros(len(p), dtype=np.int64) if outside is None else np.asarray(outside, dtype=np.int64).reshape(-1)
        fr_new = None if frames is None else np.asarray(frames, dtype=np.int64).reshape(-1)
        if not ok.all():
            p = p[ok]
            out_new = out_new[ok]
            fr_new = None if fr_new is None else fr_new[ok]
        if len(p) == 0:
            return
        # existing voxel means carry their hit counts as weights
        w = np.concatenate([self.hits, np.ones(len(p), dtype=np.int64)]).astype(np.float64)
        pos = np.vstack([self.points, p]) if len(self.points) else p
        kfs = np.concatenate([self.point_kf, np.full(len(p), kf, dtype=np.int64)])
        keys = np.floor(pos / self.voxel_m).astype(np.int64)
        key1 = (keys[:, 0] + (1 << 31)) * (1 << 32) + (keys[:, 1] + (1 << 31))
        inv, n = _unique_inverse(key1)
        wsum = np.bincount(inv, weights=w, minlength=n)
        sx = np.bincount(inv, weights=pos[:, 0] * w, minlength=n)
        sy = np.bincount(inv, weights=pos[:, 1] * w, minlength=n)
        kf_out = np.full(n, NO_KEYFRAME, dtype=np.int64)
        np.maximum.at(kf_out, inv, kfs)
        m_old = len(self.hits)
        fr_out = np.bincount(inv[:m_old], weights=self.frames.astype(np.float64), minlength=n).astype(np.float64)  # (int when empty)
        if fr_new is None:
            touched = np.zeros(n, dtype=bool)
            touched[inv[m_old:]] = True
            fr_out += touched
        else:
            fr_out += np.bincount(inv[m_old:], weights=fr_new.astype(np.float64), minlength=n)
        if self.outside.any() or out_new.any():
            out_all = np.concatenate([self.outside, out_new]).astype(np.float64)
            self.outside = np.rint(np.bincount(inv, weights=out_all, minlength=n)).astype(np.int64)
        else:
            self.outside = np.zeros(n, dtype=np.int64)
        self.points = np.empty((n, 2))
        np.divide(sx, wsum, out=self.points[:, 0])
        np.divide(sy, wsum, out=self.points[:, 1])
        self.hits = np.rint(wsum).astype(np.int64)
        self.frames = np.rint(fr_out).astype(np.int64)
        self.point_kf = kf_out
        if len(self.points) > self.max_points:
            keep = np.argsort(-self.hits, kind="stable")[: self.max_points]
            keep.sort()
            self.points, self.hits, self.point_kf = self.points[keep], self.hits[keep], self.point_kf[keep]
            self.outside, self.frames = self.outside[keep], self.frames[keep]

    def keep_points(self, keep: NDArray[np.bool_]) -> None:
        """Keep only the voxels where ``keep`` ``(N,)`` is True (with their hits, keyframes and counts)."""
        self.points, self.hits, self.point_kf = self.points[keep], self.hits[keep], self.point_kf[keep]
        self.outside, self.frames = self.outside[keep], self.frames[keep]

    def mark_outside(self, seen: NDArray[np.bool_]) -> bool:
        """One more view outside the object's box for each voxel where ``seen`` ``(N,)`` is True; True if
        that changed which voxels shape the object (:meth:`trusted`, at ``outside_ratio``)."""
        if not seen.any():
            return False
        before = self.trusted()
        self.outside[seen] += 1
        after = self.trusted()
        if (before is None and after is None) or (before is not None and after is not None and np.array_equal(before, after)):
            return False
        self.points_revision += 1  # the shape's cache (footprint_estimate._point_shape) is stale
        return True

    def trusted(self) -> NDArray[np.bool_] | None:
        """``(N,)`` the voxels that still shape the object: not seen outside its box in at least two views
        and more often than ``outside_ratio`` × their hits; ``None`` if that is every voxel."""
        if self.outside_ratio <= 0.0 or not len(self.outside):
            return None
        bad = (self.outside >= 2) & (self.outside > self.outside_ratio * self.hits)
        if not bad.any() or bad.all():
            return None
        return ~bad

    def add_ray(
        self,
        origin: FloatArray,
        direction: FloatArray,
        weight: float,
        kf: int = NO_KEYFRAME,
        decay: float = 1.0,
        apparent_width: float = float("nan"),
        open_side: int = 0,
        base_range: float = float("nan"),
    ) -> None:
        """Add a bisector ray (object frame); older rays' weights are multiplied by ``decay`` first.

        ``apparent_width``: the object's width across the ray as the box shows it (m), NaN if unknown.
        ``open_side``: +1 if the box was cut by the image's left border (the ray is then that border's
        half-line and the object continues to its left), −1 for the right border, 0 otherwise.
        ``base_range``: how far along the ray the box's bottom edge meets the floor (where the object's base
        begins, m), NaN if the box is cut by the image's bottom or unknown.
        """
        d = np.asarray(direction, dtype=np.float64).reshape(2)
        n = math.sqrt(float(d.dot(d)))  # np.linalg.norm's value (its dot product), without its overhead
        o = np.asarray(origin, dtype=np.float64).reshape(2)
        if n < 1e-12 or not np.isfinite(n) or not (math.isfinite(o[0]) and math.isfinite(o[1])):
            return
        d = d / n
        m = len(self.ray_weight)
        self.ray_origin = _appended(self.ray_origin, o)
        self.ray_dir = _appended(self.ray_dir, d)
        w = np.empty(m + 1)
        np.multiply(self.ray_weight, decay, out=w[:m])
        w[m] = float(weight)
        self.ray_weight = w
        self.ray_kf = _appended(self.ray_kf, int(kf))
        self.ray_app = _appended(self.ray_app, float(apparent_width))
        self.ray_open = _appended(self.ray_open, int(open_side))
        self.ray_base = _appended(self.ray_base, float(base_range))
        if m + 1 > self.max_rays:
            # keep the viewpoints spread out: drop the older ray of the closest pair of origins
            o_all = self.ray_origin
            dx = o_all[:, 0][:, None] - o_all[:, 0][None, :]
            dy = o_all[:, 1][:, None] - o_all[:, 1][None, :]
            d2 = dx * dx + dy * dy  # the squared distances as np.sum(Δ ** 2, axis=-1) adds them
            d2[_lower_triangle(len(o_all))] = np.inf
            i, _j = np.unravel_index(np.argmin(d2), d2.shape)
            keep = np.ones(len(o_all), dtype=bool)
            keep[i] = False
            self.ray_origin, self.ray_dir = self.ray_origin[keep], self.ray_dir[keep]
            self.ray_weight, self.ray_kf, self.ray_app = self.ray_weight[keep], self.ray_kf[keep], self.ray_app[keep]
            self.ray_open, self.ray_base = self.ray_open[keep], self.ray_base[keep]

    def add_ground_center(self, center: FloatArray, weight_old: float, kf: int = NO_KEYFRAME) -> None:
        """Rolling average of ground-plane centres: ``c ← w·c + (1 − w)·new`` (paper's 90 %)."""
        c = np.asarray(center, dtype=np.float64).reshape(2)
        if not np.all(np.isfinite(c)):
            return
        self.gp_center = c.copy() if self.gp_center is None else weight_old * self.gp_center + (1.0 - weight_old) * c
        self.gp_kf = int(kf)

    def absorb(self, other: ObjectEvidence) -> None:
        """Merge another object's evidence into this one (same class, same object)."""
        if other.has_points:
            for k in np.unique(other.point_kf):
                m = other.point_kf == k
                # repeat points by hits to keep their weight; the first copy carries the outside and view counts
                h = other.hits[m]
                first = np.concatenate([[0], np.cumsum(h)[:-1]])
                out = np.zeros(int(h.sum()), dtype=np.int64)
                out[first] = other.outside[m]
                fr = np.zeros(int(h.sum()), dtype=np.int64)
                fr[first] = other.frames[m]
                self.add_points(np.repeat(other.points[m], h, axis=0), int(k), out, fr)
        for o, d, w, k, a, op, br in zip(other.ray_origin, other.ray_dir, other.ray_weight, other.ray_kf, other.ray_app,
                                         other.ray_open, other.ray_base):
            self.add_ray(o, d, float(w), int(k), apparent_width=float(a), open_side=int(op), base_range=float(br))
        self.support_obs += other.support_obs
        self.corner_obs += other.corner_obs
        self.observations += other.observations
        self.leg_obs += other.leg_obs
        if other.gp_center is not None:
            if self.gp_center is None:
                self.gp_center, self.gp_kf = other.gp_center.copy(), other.gp_kf
            else:
                self.gp_center = 0.5 * (self.gp_center + other.gp_center)

    # -- corrections -----------------------------------------------------------------------------
    def transform(self, deltas: dict[int, Pose2]) -> bool:
        """Move every piece seen from keyframe ``k`` by ``deltas[k]`` (``T_map_kf_new ∘ T_map_kf_old⁻¹``).
        Returns False if no piece was seen from those keyframes (nothing moved)."""
        if not self._seen_from(deltas):
            return False
        if len(deltas) > 8:
            self._transform_many(deltas)
            return True
        for k, T in deltas.items():
            m = self.point_kf == k
            if np.any(m):
                self.points[m] = T.transform_points(self.points[m])
                self.points_revision += 1
            m = self.ray_kf == k
            if np.any(m):
                self.ray_origin[m] = T.transform_points(self.ray_origin[m])
                c, s = np.cos(T.yaw), np.sin(T.yaw)
                d = self.ray_dir[m]
                self.ray_dir[m] = np.stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1]], axis=1)
            if self.gp_center is not None and self.gp_kf == k:
                self.gp_center = T.transform_points(self.gp_center[None, :])[0]
        return True

    def _seen_from(self, deltas: dict[int, Pose2]) -> bool:
        """True if a point, a ray or the ground-plane centre was seen from a keyframe of ``deltas``."""
        if self.gp_center is not None and self.gp_kf in deltas:
            return True
        ks = np.fromiter(deltas, dtype=np.int64, count=len(deltas))
        return bool(np.isin(self.point_kf, ks).any() or np.isin(self.ray_kf, ks).any())

    def _transform_many(self, deltas: dict[int, Pose2]) -> None:
        """:meth:`transform` for many keyframes at once (a loop closure moves most of them): each piece
        looks its keyframe's delta up instead of one mask per keyframe; the same arithmetic
        (``Pose2.transform_points``' per element, cos/sin of each delta's yaw as there)."""
        ks = np.array(sorted(deltas), dtype=np.int64)
        poses = [deltas[int(k)] for k in ks]
        tx = np.array([T.x for T in poses])
        ty = np.array([T.y for T in poses])
        cs = np.array([math.cos(T.yaw) for T in poses])  # as Pose2.transform_points
        sn = np.array([math.sin(T.yaw) for T in poses])

        def lookup(kf: NDArray[np.int64]) -> tuple[NDArray[np.bool_], NDArray[np.int64]]:
            j = np.clip(np.searchsorted(ks, kf), 0, len(ks) - 1)
            return ks[j] == kf, j

        m, j = lookup(self.point_kf)
        if np.any(m):
            j = j[m]
            p = self.points[m]
            out = np.empty_like(p)
            out[:, 0] = cs[j] * p[:, 0] - sn[j] * p[:, 1] + tx[j]
            out[:, 1] = sn[j] * p[:, 0] + cs[j] * p[:, 1] + ty[j]
            self.points[m] = out
            self.points_revision += 1
        m, j = lookup(self.ray_kf)
        if np.any(m):
            j = j[m]
            o = self.ray_origin[m]
            out = np.empty_like(o)
            out[:, 0] = cs[j] * o[:, 0] - sn[j] * o[:, 1] + tx[j]
            out[:, 1] = sn[j] * o[:, 0] + cs[j] * o[:, 1] + ty[j]
            self.ray_origin[m] = out
            d = self.ray_dir[m]
            self.ray_dir[m] = np.stack([cs[j] * d[:, 0] - sn[j] * d[:, 1], sn[j] * d[:, 0] + cs[j] * d[:, 1]], axis=1)
        if self.gp_center is not None and self.gp_kf in deltas:
            self.gp_center = deltas[self.gp_kf].transform_points(self.gp_center[None, :])[0]

    def latest_keyframe(self) -> int:
        ks = [int(self.point_kf.max()) if len(self.point_kf) else NO_KEYFRAME]
        ks.append(int(self.ray_kf.max()) if len(self.ray_kf) else NO_KEYFRAME)
        ks.append(self.gp_kf)
        return max(ks)

    # -- (de)serialisation -----------------------------------------------------------------------
    def state_dict(self) -> dict:
        return {
            "voxel_m": self.voxel_m,
            "points": self.points.tolist(),
            "hits": self.hits.tolist(),
            "frames": self.frames.tolist(),
            "point_kf": self.point_kf.tolist(),
            "outside": self.outside.tolist(),
            "ray_origin": self.ray_origin.tolist(),
            "ray_dir": self.ray_dir.tolist(),
            "ray_weight": self.ray_weight.tolist(),
            "ray_kf": self.ray_kf.tolist(),
            "ray_app": _nan_list(self.ray_app),
            "ray_open": self.ray_open.tolist(),
            "ray_base": _nan_list(self.ray_base),
            "gp_center": None if self.gp_center is None else self.gp_center.tolist(),
            "gp_kf": self.gp_kf,
            "support_obs": self.support_obs,
            "corner_obs": self.corner_obs,
            "observations": self.observations,
            "leg_obs": self.leg_obs,
        }

    @staticmethod
    def from_state_dict(d: dict) -> ObjectEvidence:
        e = ObjectEvidence(voxel_m=float(d.get("voxel_m", 0.03)))
        e.points = np.asarray(d.get("points", []), dtype=np.float64).reshape(-1, 2)
        e.hits = np.asarray(d.get("hits", []), dtype=np.int64).reshape(-1)
        e.frames = np.asarray(d.get("frames", e.hits), dtype=np.int64).reshape(-1)  # states saved before it: its hits
        e.point_kf = np.asarray(d.get("point_kf", []), dtype=np.int64).reshape(-1)
        e.outside = np.asarray(d.get("outside", [0] * len(e.hits)), dtype=np.int64).reshape(-1)
        e.ray_origin = np.asarray(d.get("ray_origin", []), dtype=np.float64).reshape(-1, 2)
        e.ray_dir = np.asarray(d.get("ray_dir", []), dtype=np.float64).reshape(-1, 2)
        e.ray_weight = np.asarray(d.get("ray_weight", []), dtype=np.float64).reshape(-1)
        e.ray_kf = np.asarray(d.get("ray_kf", []), dtype=np.int64).reshape(-1)
        e.ray_open = np.asarray(d.get("ray_open", [0] * len(e.ray_kf)), dtype=np.int64).reshape(-1)
        e.ray_app = _nan_array(d.get("ray_app"), len(e.ray_kf))
        e.ray_base = _nan_array(d.get("ray_base"), len(e.ray_kf))  # absent in states saved before it: unknown
        gp = d.get("gp_center")
        e.gp_center = None if gp is None else np.asarray(gp, dtype=np.float64).reshape(2)
        e.gp_kf = int(d.get("gp_kf", NO_KEYFRAME))
        e.support_obs = int(d.get("support_obs", 0))
        e.corner_obs = int(d.get("corner_obs", 0))
        e.observations = int(d.get("observations", 0))
        e.leg_obs = int(d.get("leg_obs", 0))
        if not (len(e.points) == len(e.hits) == len(e.frames) == len(e.point_kf) == len(e.outside)) or not (
            len(e.ray_origin) == len(e.ray_dir) == len(e.ray_weight) == len(e.ray_kf) == len(e.ray_app) == len(e.ray_open)
            == len(e.ray_base)
        ):
            raise ValueError("object evidence: array lengths differ")
        return e
