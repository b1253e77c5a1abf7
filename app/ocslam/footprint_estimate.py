"""An object's footprint, estimated from its accumulated evidence (improved mode).

The footprint (:func:`estimate_footprint`) is the minimum-area rectangle of the points of an
:class:`~app.ocslam.evidence.ObjectEvidence`, completed to the class's size on the sides the robot
never saw (a sofa seen from the front is as deep as a sofa), positioned where the bisector rays cross
(least squares, :mod:`app.ocslam.ray_centre`) inside the range the points allow. All in the object
frame (``map``).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from app.ocslam.classes import ClassPrior
from app.ocslam.evidence import ObjectEvidence
from app.ocslam.footprint import Footprint, min_area_rect, nearest_distances
from app.ocslam.free_space import FreeFn, extension_free, far_legs_free, legs_seen_free
from app.ocslam.ray_centre import ray_consistent, ray_normal_equations, solve2
from app.ocslam.unseen_part import unseen_part_conflict

FloatArray = NDArray[np.float64]
#: A voxel seen rarely and farther than this from every well-seen voxel is a stray (m).
_STRAY_M = 0.3
#: A voxel seen in this many frames is the object's, however often its best voxel was seen (principle 39).
_STRAY_MIN_VIEWS = 3


def _box_qp(H: FloatArray, g: FloatArray, lo: FloatArray, hi: FloatArray) -> FloatArray:
    """argmin ``½ sᵀHs − gᵀs`` over the box ``lo ≤ s ≤ hi`` (2D, H positive definite)."""
    s = solve2(H, g)
    if lo[0] - 1e-12 <= s[0] <= hi[0] + 1e-12 and lo[1] - 1e-12 <= s[1] <= hi[1] + 1e-12:
        return s

    def f(x: FloatArray) -> float:
        return float(0.5 * x @ H @ x - g @ x)

    cands = []
    for i in range(2):
        j = 1 - i
        for v in (lo[i], hi[i]):
            # fix s_i = v, minimise over s_j
            sj = (g[j] - H[j, i] * v) / H[j, j]
            x = np.empty(2)
            x[i], x[j] = v, np.clip(sj, lo[j], hi[j])
            cands.append(x)
    return min(cands, key=f)


def _median(v: FloatArray) -> float:
    """``np.median`` of a non-empty finite ``(N,)`` array (the same value, without its overhead)."""
    s = np.sort(v)
    n = len(s)
    return float(s[n // 2]) if n % 2 else float((s[n // 2 - 1] + s[n // 2]) / 2.0)


def _one_sided_axes(viewpoints: FloatArray, center: FloatArray, axes: FloatArray, half: FloatArray) -> list[int]:
    """For each row of ``axes`` ``(2, 2)``: +1/−1 if every viewpoint outside the slab
    ``|(v − c)·axis| ≤ half + 5 cm`` (``half`` ``(2,)``) is on that side, else 0."""
    if len(viewpoints) == 0:
        return [0, 0]
    rel = viewpoints - center[None, :]
    out = []
    for i in range(2):
        s = rel @ axes[i]
        o = s[np.abs(s) > half[i] + 0.05]
        out.append(0 if len(o) == 0 else 1 if o.min() > 0 else -1 if o.max() < 0 else 0)
    return out


def depth_for_width(width: float, pc: ClassPrior, legs: bool = False) -> tuple[float, float, float]:
    """``(nominal, min, max)`` depth of an object of class ``pc`` whose visible face is ``width`` wide.

    Matches the face against the sides of the class's typical footprints (each within ±30 % scale) —
    of its legs' footprints when the face is made of legs; without a match, the class's width range
    (a face wider than any width is a length).
    """
    best: tuple[float, float] | None = None
    for a, b in (pc.leg_shapes if legs and pc.leg_shapes else pc.shapes):
        for face, other in ((a, b), (b, a)):
            sc = width / face
            if 0.7 <= sc <= 1.3:
                score = abs(math.log(sc))
                if best is None or score < best[0] - 1e-9:
                    best = (score, other * sc)
    if best is not None:
        d = best[1]
        return d, 0.8 * d, 1.25 * d
    if width > pc.width[2]:
        return pc.width[1], pc.width[0], pc.width[2]
    return pc.width[1], pc.width[0], pc.length[2]



def _centred(center: FloatArray, th: float, d_obs: FloatArray, pc: ClassPrior, w_app: float) -> Footprint:
    """The footprint centred on the points: the class's first shape, or a disc as wide as the boxes (``w_app``,
    when finite) for a central support, never smaller than the points' extents ``d_obs`` (rectangle axes)."""
    a, b = pc.shapes[0] if pc.shapes else (pc.length[1], pc.width[1])
    if np.isfinite(w_app):
        a = b = float(np.clip(w_app, pc.width[0], pc.length[2]))
    first = d_obs[0] >= d_obs[1]
    return Footprint(center, th, float(max(d_obs[0], a if first else b)), float(max(d_obs[1], b if first else a)))


def _base_before(ev: ObjectEvidence, axis: FloatArray, face: float, side: int) -> float:
    """How far in front of the face at ``face`` along ``axis`` (``(2,)``, the viewpoints on its ``side`` ±1) the
    boxes' bottom edges put the object's base: the median over the rays that know it (``ev.ray_base``) of the
    distance, along ``axis``, from the face to where each ray meets the floor under its box's bottom edge
    (positive: nearer the viewpoints than the face; −inf if no ray knows it)."""
    m = np.isfinite(ev.ray_base)
    if not m.any():
        return -math.inf
    base = ev.ray_origin[m] + ev.ray_base[m][:, None] * ev.ray_dir[m]
    return _median(side * (base @ axis - face))


def _point_shape(ev: ObjectEvidence) -> tuple[FloatArray, NDArray[np.int64], float, FloatArray, FloatArray]:
    """``(points, hits, theta, lo, hi)``: the evidence's points without strays and their rectangle
    (:func:`min_area_rect`), read-only. Kept on the evidence until its points change (a new ``points``
    or ``hits`` array, or ``points_revision``): a bisector ray alone, or a correction of other
    keyframes, leaves them as they were."""
    c = ev.shape_cache
    key = (ev.points_revision, ev.outside_ratio, ev.stray_by_views)
    if c is not None and c[0] is ev.points and c[1] is ev.hits and c[2] == key:
        return c[3], c[4], c[5], c[6], c[7]
    points, all_hits = ev.points, ev.hits
    seen = ev.frames if ev.stray_by_views else ev.hits  # how often each voxel was seen (principle 45)
    trusted = ev.trusted()  # voxels seen outside the object's own box from other viewpoints do not shape it
    if trusted is not None:
        points, all_hits, seen = points[trusted], all_hits[trusted], seen[trusted]
    # stray points that once joined the object (a background point between a pedestal table's legs) do
    # not shape it: voxels seen in under a tenth of the best voxel's views AND away from every well-seen
    # voxel are ignored — but a voxel seen in _STRAY_MIN_VIEWS views is never a stray (principle 39: a
    # four-legged table's far legs, seen in a few frames while views of its near leg alone piled up). A view
    # counts once per voxel (``ev.frames``, principle 45): a near leg gives several points a frame, a far one one
    strong = seen >= min(max(1.0, 0.1 * float(seen.max())), float(_STRAY_MIN_VIEWS))
    n_strong = int(np.count_nonzero(strong))
    if n_strong == len(strong) or n_strong == 0:
        pts, hits = points, all_hits
    else:
        keep = strong.copy()
        weak = ~strong
        keep[weak] = nearest_distances(points[weak], points[strong]) <= _STRAY_M
        pts, hits = points[keep], all_hits[keep]
    th, lo, hi = min_area_rect(pts)
    # the cache holds the arrays it was computed from, so their identities cannot be reused meanwhile
    ev.shape_cache = (ev.points, ev.hits, key, pts, hits, th, lo, hi)
    return pts, hits, th, lo, hi


def estimate_footprint(
    ev: ObjectEvidence,
    pc: ClassPrior,
    ray_prior_weight: float = 1.0,
    known_free: FreeFn | None = None,
    depth_axis_hint: int | None = None,
) -> Footprint | None:
    """The object's footprint from its evidence and class prior (object frame). ``None`` if no evidence.

    1. The minimum-area rectangle of the points gives the orientation and the observed extents.
    2. The *depth* axis is the one most aligned with the viewing directions, the other is *tangential*.
       The box's apparent width measures the tangential extent; a tangential extent smaller than it
       means part of the object was hidden or is not at the LIDAR height (legs); points spread wider
       than ``ev.box_width_cap`` times it (``consciousness.box_width_cap``) are partly something else's.
    3. Seen from one side only, the object extends away from the robot by the depth of the typical
       footprint whose face matches its width (:func:`depth_for_width`) — or, for an open frame whose boxes'
       bottom edges put its base more than half that depth in front of the face (``ev.far_face``,
       :func:`_base_before`), towards the robot: the face was its far side, seen through its open front.
    4. The centre is the least-squares crossing of the bisector rays, constrained to the interval the
       points and sizes allow on each axis.

    Seen only through boxes cut by the image border (no bisector ray), the points are kept as they
    are, except that a single face (a line of points) still gets its depth (step 3).

    A legged object seen as one small support on the box's centre line (a pedestal table) keeps its
    centre on that support; so does one completed from a single support when the grid knows free space where
    two of its other legs would stand (``known_free.legs_free``, ``consciousness.legs_seen_free``, classes
    that may stand on a pedestal). ``known_free`` (``(N, 2)`` points → ``(N,)`` True where the occupancy grid
    knows free space) vetoes an extension into space the LIDAR has seen empty: the points were then the
    object's far side (an open shelf seen from inside).

    Where ``known_free`` also knows obstacles (its ``occupied`` method, :class:`~app.ocslam.free_space.GridSpace`),
    the part of the footprint the points do not show must lie behind the object's own face: when most of it
    is seen, from every viewpoint, only through an obstacle away from the points (a wall), the object is
    turned the other way round (``depth_axis_hint``: the rectangle axis of the points taken as the depth
    axis), and kept to its points when that is no better (:func:`unseen_part_conflict`).
    """
    L, W = pc.length, pc.width
    if not ev.has_points:
        if ev.gp_center is None:
            return None
        yaw = 0.0
        if len(ev.ray_dir):
            d = ev.ray_dir[-1]
            yaw = float(np.arctan2(d[1], d[0]) + np.pi / 2)
        a, b = pc.shapes[0] if pc.shapes else (L[1], W[1])
        # the ground-plane placements (rolling average) fix the range, the bisector rays the bearing
        H = ray_prior_weight * np.eye(2)
        g = ray_prior_weight * ev.gp_center
        use = ev.ray_weight > 1e-6
        if np.any(use):
            _, _, H_rays, g_rays = ray_normal_equations(ev, use)
            H = H + H_rays
            g = g + g_rays
        return Footprint(np.asarray(np.linalg.solve(H, g), dtype=np.float64), yaw, a, b)

    pts, hits, th, lo, hi = _point_shape(ev)
    keep, c_ray = ray_consistent(ev, pts)
    if keep is not None and c_ray is not None:
        if int(np.count_nonzero(keep)) < 3:
            # every point lies beyond the object's reach of where its rays cross: they are something else's
            # (a box beside a shelf that the LIDAR sees through); the rays place it, at its nominal shape
            d = ev.ray_dir[-1]
            a, b = pc.shapes[0] if pc.shapes else (L[1], W[1])
            return Footprint(c_ray, float(np.arctan2(d[1], d[0]) + np.pi / 2), a, b)
        rc = ev.ray_shape_cache  # the same voxels as last time (the usual case): their rectangle is known
        if rc is not None and rc[0] is pts and np.array_equal(rc[1], keep):
            pts, hits, th, lo, hi = rc[2:]
        else:
            kept, hits = pts[keep], hits[keep]
            th, lo, hi = min_area_rect(kept)
            ev.ray_shape_cache = (pts, keep, kept, hits, th, lo, hi)
            pts = kept
    axes = np.array([[np.cos(th), np.sin(th)], [-np.sin(th), np.cos(th)]])
    d_obs = hi - lo
    mid = 0.5 * (lo + hi)
    center0 = axes.T @ mid
    views = ev.ray_origin
    side = _one_sided_axes(views, center0, axes, d_obs / 2)
    depth_axis = -1
    one_face = False
    if depth_axis_hint is not None and len(views):
        depth_axis = int(depth_axis_hint)
    elif len(views):
        long_ax = int(np.argmax(d_obs))
        if d_obs[long_ax] >= 0.15 and d_obs[1 - long_ax] <= 0.35 * d_obs[long_ax]:
            # one face (a line of points), even seen obliquely: its normal is the depth axis
            depth_axis = 1 - long_ax
            one_face = True
        else:
            u = center0[None, :] - views
            u = u / np.maximum(np.sqrt(u[:, 0:1] * u[:, 0:1] + u[:, 1:2] * u[:, 1:2]), 1e-9)  # row norms
            depth_axis = int((np.add.reduce(np.abs(u @ axes.T), axis=0) / len(u)).argmax())  # the mean's value
    tan_axis = 1 - depth_axis if depth_axis >= 0 else -1

    w_app = float("nan")
    if tan_axis >= 0 and len(ev.ray_app):
        along = np.abs(ev.ray_dir @ axes[depth_axis]) > 0.85
        vals = ev.ray_app[along & np.isfinite(ev.ray_app)]
        if len(vals):
            w_app = _median(vals)

    use = ev.ray_weight > 1e-6  # rays that place the centre (boxes not cut by the image border)
    any_use = bool(use.any())
    cut_only = not any_use and len(views) > 0
    if cut_only and not one_face:
        # seen only through boxes cut by the image border: the rest is outside the image, anywhere
        # from the border round to the robot's side, so nothing is extrapolated; fragments of one
        # object join later when they meet (Consciousness)
        return Footprint(center0, th, float(max(d_obs[0], 0.05)), float(max(d_obs[1], 0.05)))
    # A single face seen through cut boxes (a sofa's end filling the frame) still hides the object's
    # depth behind it: the face's extent is kept as seen and the depth is extrapolated below.
    support = (
        not cut_only and pc.legged and ev.support_obs > ev.corner_obs and max(d_obs) <= pc.leg_size_max * 1.5
    )
    if depth_axis < 0 or support:
        # no viewpoint (or a central support): the points are the object's centre
        return _centred(center0, th, d_obs, pc, w_app if support else float("nan"))

    # tangential extent: the observed one if it covers the box's apparent width, else the apparent width
    tan_complete = cut_only or (np.isfinite(w_app) and d_obs[tan_axis] >= 0.75 * w_app)
    if tan_complete:
        t_tan = float(d_obs[tan_axis])
    elif np.isfinite(w_app):
        t_tan = float(np.clip(w_app, max(d_obs[tan_axis], W[0]), L[2]))
    else:
        t_tan = float(max(d_obs[tan_axis], L[1] if d_obs[tan_axis] > W[2] else W[1]))
    legs = pc.legged and ev.leg_obs * 2 > ev.observations
    dep_nom, dep_min, dep_max = depth_for_width(t_tan, pc, legs)
    tan_max = L[2] if t_tan > W[2] else max(L[2], W[2])
    k = float(ev.box_width_cap)
    if k > 0.0 and np.isfinite(w_app):
        # across the line of sight the object is no wider than its boxes show it: points spread wider are
        # partly something else's (a table's legs beside a chair's), not a wider instance of the class
        tan_max = min(tan_max, max(k * w_app, w_app + 0.2))

    s_lo, s_hi, s_prior, size, lam = np.zeros(2), np.zeros(2), np.zeros(2), np.zeros(2), np.ones(2)
    for i in range(2):
        cap = tan_max if i == tan_axis else max(dep_max, W[2])
        if d_obs[i] > cap * 1.15:
            # over-extended evidence (background points): the object is somewhere inside it
            size[i] = cap
            s_lo[i], s_hi[i] = lo[i] + cap / 2, hi[i] - cap / 2
            w = hits.astype(np.float64)
            proj = pts @ axes[i]
            s_prior[i] = float(np.clip(np.sum(proj * w) / max(np.sum(w), 1e-9), s_lo[i], s_hi[i]))
        elif i == tan_axis:
            if tan_complete:
                size[i] = d_obs[i]
                slack = 0.05 * d_obs[i] + 0.01
                s_lo[i], s_hi[i] = mid[i] - slack, mid[i] + slack
                s_prior[i] = mid[i]
                s_prior[i] = mid[i]
            else:
                # incomplete (occluded, or legs): it spans the observed part and at most its size; the rays decide
                t_max = max(d_obs[i], 1.25 * t_tan)
                size[i] = max(d_obs[i], t_tan)
                s_lo[i], s_hi[i] = hi[i] - t_max / 2, lo[i] + t_max / 2
                lam[i] = 0.1
                s_prior[i] = mid[i]
        elif side[i] == 0 or d_obs[i] >= dep_nom:
            size[i] = d_obs[i]
            slack = 0.05 * d_obs[i] + 0.01
            s_lo[i], s_hi[i] = mid[i] - slack, mid[i] + slack
            s_prior[i] = mid[i]
        elif known_free is not None and (
            far_legs_free(known_free, axes, i, lo, hi, -side[i], dep_nom - d_obs[i])
            if legs and ev.legs_extend
            else extension_free(known_free, axes, i, lo, hi, -side[i], dep_nom - d_obs[i])
        ):
            # the space it would extend into is known free: keep what was seen
            size[i] = max(d_obs[i], 0.05)
            slack = 0.05 * d_obs[i] + 0.01
            s_lo[i], s_hi[i] = mid[i] - slack, mid[i] + slack
            s_prior[i] = mid[i]
        else:
            # seen from one side only: the object extends away from the robot by its depth
            sgn = side[i]
            face = hi[i] if sgn > 0 else lo[i]
            t_nom, t_min, t_max = max(d_obs[i], dep_nom), max(d_obs[i], dep_min), max(d_obs[i], dep_max)
            if ev.far_face and pc.open_span and not pc.on_wall and _base_before(ev, axes[i], face, sgn) > 0.5 * t_nom:
                # an open frame's far side seen through its open front: it extends towards the robot
                sgn = -sgn
                face = hi[i] if sgn > 0 else lo[i]
            size[i] = t_nom
            c_min, c_max = face - sgn * t_min / 2, face - sgn * t_max / 2
            s_lo[i], s_hi[i] = min(c_min, c_max), max(c_min, c_max)
            s_prior[i] = face - sgn * t_nom / 2

    # least squares: the centre near every weighted bisector ray, regularised towards the prior
    H = np.array([[ray_prior_weight * lam[0], 0.0], [0.0, ray_prior_weight * lam[1]]])  # w · diag(λ)
    g = ray_prior_weight * lam * s_prior
    if any_use:
        _, _, H_rays, g_rays = ray_normal_equations(ev, use, axes)  # in rectangle coordinates
        H = H + H_rays
        g = g + g_rays
    s_opt = _box_qp(H, g, s_lo, s_hi)
    if c_ray is not None:
        # the rays fixed the centre and the points were chosen around it: it stays there
        s_opt = axes @ c_ray
    # the rectangle must still cover the observed points (unless they are over-extended)
    for i in range(2):
        cap = tan_max if i == tan_axis else max(dep_max, W[2])
        if d_obs[i] <= cap * 1.15:
            size[i] = max(size[i], 2.0 * max(s_opt[i] - lo[i], hi[i] - s_opt[i]))
    center = axes.T @ s_opt
    fp = Footprint(center, th, float(size[0]), float(size[1]))
    if (
        known_free is not None and pc.pedestal and getattr(known_free, "legs_free", False)
        and max(d_obs) <= pc.leg_size_max * 1.5 and min(fp.size_x, fp.size_y) >= pc.width[0]
        and legs_seen_free(known_free, fp, pts, pc.leg_size_max)
    ):
        # one support, and where the legs of the object completed from it would stand the LIDAR saw free space:
        # that support is its centre (a pedestal seen off its boxes' centre lines), not one of its legs
        return _centred(center0, th, d_obs, pc, w_app)
    occupied = getattr(known_free, "occupied", None)
    if occupied is None or depth_axis_hint is not None:
        return fp
    if unseen_part_conflict(occupied, views, pts, axes, lo, hi, s_opt, size) <= 0.5:
        return fp
    alt = estimate_footprint(ev, pc, ray_prior_weight, known_free, depth_axis_hint=1 - depth_axis)
    if alt is not None:
        s_alt = axes @ alt.center
        if unseen_part_conflict(occupied, views, pts, axes, lo, hi, s_alt, np.array([alt.size_x, alt.size_y])) <= 0.5:
            return alt
    return Footprint(center0, th, float(max(d_obs[0], 0.05)), float(max(d_obs[1], 0.05)))
