"""Where an object's bisector rays cross (improved mode, principle 10 of docs/consciousness.md).

Every box that saw an object adds a ray from the camera along the box's bisector, weighted by how much
it says (:class:`~app.ocslam.evidence.ObjectEvidence`). Their least-squares crossing is where the object
is, and how well it is fixed follows from the rays' residuals and the spread of their directions (rays
from one direction fix nothing along it). Where the rays fix the centre well, LIDAR points beyond the
object's reach of it are something else's (a stool behind a round table, a box beside a shelf).
All in the object frame (``map``).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from app.ocslam.evidence import ObjectEvidence

FloatArray = NDArray[np.float64]

#: how far ahead of every camera that saw it a crossing of the bisectors must lie (m)
_MIN_AHEAD_M = 0.1


def solve2(H: FloatArray, g: FloatArray) -> FloatArray:
    """``H⁻¹ g`` for a 2×2 ``H``: LU with partial pivoting in Python floats (numpy's ``linalg.solve``
    costs more than the arithmetic on a 2×2 system)."""
    (a, b), (c, d) = H.tolist()
    g0, g1 = g.tolist()
    if abs(c) > abs(a):  # pivot: swap the rows
        a, b, c, d, g0, g1 = c, d, a, b, g1, g0
    if a == 0.0:
        raise np.linalg.LinAlgError("Singular matrix")
    m = c / a
    u = d - m * b
    if u == 0.0:
        raise np.linalg.LinAlgError("Singular matrix")
    x1 = (g1 - m * g0) / u
    return np.array([(g0 - b * x1) / a, x1])


def ray_normal_equations(
    ev: ObjectEvidence, use: NDArray[np.bool_], axes: FloatArray | None = None
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The weighted bisector rays ``use`` of ``ev`` as least-squares lines ``n·x = off``: their unit
    normals ``(K, 2)`` and offsets ``(K,)``, and the normal equations ``H (2, 2)``, ``g (2,)`` of
    ``Σ w (n·x − off)²``. ``axes``: ``(2, 2)`` rows of another frame's axes (the rectangle's) to
    express them in; ``None``: the object frame."""
    d = ev.ray_dir[use]
    n = np.empty_like(d)
    np.negative(d[:, 1], out=n[:, 0])
    n[:, 1] = d[:, 0]
    o = ev.ray_origin[use]
    if axes is not None:
        n, o = n @ axes.T, o @ axes.T
    w = ev.ray_weight[use]
    off = np.add.reduce(n * o, axis=1)  # np.sum's value, without its wrapper
    return n, off, (n * w[:, None]).T @ n, np.add.reduce(n * (w * off)[:, None], axis=0)


def ray_centre(ev: ObjectEvidence) -> tuple[FloatArray, float] | None:
    """``(centre (2,), σ (m))``: where the object's weighted bisector rays cross (least squares, object
    frame) and how well they fix it: the rays' 90th-percentile residual over the square root of the
    smallest eigenvalue of their information matrix (rays from one direction fix nothing along it).
    ``None`` with fewer than four rays, parallel ones, or a crossing less than ``_MIN_AHEAD_M`` ahead of a camera
    (the lines cross behind it: the rays do not meet)."""
    use = ev.ray_weight > 1e-6
    if int(np.count_nonzero(use)) < 4:
        return None
    n, off, H, g = ray_normal_equations(ev, use)
    (a, b), (_, c) = H.tolist()
    lam_min = 0.5 * (a + c) - math.sqrt(max(0.25 * (a - c) ** 2 + b * b, 0.0))
    if lam_min <= 1e-9:
        return None
    try:
        x = solve2(H, g)
    except np.linalg.LinAlgError:
        return None
    # a bisector is a half-line from the camera: a crossing behind a camera (lines from one stretch of path that
    # saw two objects cross near the path) places nothing
    o, d = ev.ray_origin[use], ev.ray_dir[use]
    if float(np.min((x[0] - o[:, 0]) * d[:, 0] + (x[1] - o[:, 1]) * d[:, 1])) < _MIN_AHEAD_M:
        return None
    res = np.sort(np.abs(n @ x - off))
    scale = max(float(res[int(0.9 * (len(res) - 1))]), 0.02)  # the 90th percentile: rays of two objects disagree
    return x, scale / math.sqrt(lam_min)


def ray_consistent(ev: ObjectEvidence, pts: FloatArray) -> tuple[NDArray[np.bool_] | None, FloatArray | None]:
    """``(keep, centre)``: where the rays fix the centre to ``ev.ray_centre_sigma`` (m), the voxels of
    ``pts`` ``(N, 2)`` within the object's reach of it (half the 75th percentile of its apparent widths, 15 % more, plus
    twice σ and 5 cm; a stool's legs behind a round table are beyond it). ``(None, None)`` when the rays
    do not decide (then every voxel counts); ``keep`` all False: none of the points is the object's."""
    if ev.ray_centre_sigma <= 0.0:
        return None, None
    rc = ray_centre(ev)
    if rc is None or rc[1] > ev.ray_centre_sigma:
        return None, None
    use = (ev.ray_weight > 1e-6) & np.isfinite(ev.ray_app)
    if not use.any():
        return None, None
    c, sigma = rc
    reach = 0.5 * float(np.percentile(ev.ray_app[use], 75.0)) * 1.15 + 2.0 * sigma + 0.05
    dx, dy = pts[:, 0] - c[0], pts[:, 1] - c[1]
    keep = dx * dx + dy * dy <= reach * reach
    if keep.all():
        return None, None
    if ev.ray_centre_behind_surface and in_front_of_surface(ev.ray_origin[use], ev.ray_dir[use], c, pts):
        return None, None  # the rays cross on the viewers' side of what the LIDAR saw: boxes of a part of it
    return keep, c


#: how near a ray a point must lie to be where that ray meets the object's surface (m)
ON_RAY_M = 0.1


def in_front_of_surface(origins: FloatArray, dirs: FloatArray, c: FloatArray, pts: FloatArray) -> bool:
    """True when ``c`` ``(2,)`` lies nearer the cameras than the seen surface along most rays.

    ``origins``/``dirs``: ``(R, 2)`` bisector rays (unit directions); ``pts``: ``(N, 2)`` the object's points. Along
    each ray that meets points (within :data:`ON_RAY_M` of it, ahead of the camera), the surface is the nearest of
    them; an object's centre lies behind its own surface, so a crossing in front of it on more than half of those
    rays is no centre of this object (the boxes saw a part of it, or something else)."""
    v = pts[None, :, :] - origins[:, None, :]  # (R, N, 2)
    along = v[..., 0] * dirs[:, None, 0] + v[..., 1] * dirs[:, None, 1]
    lateral = np.abs(v[..., 0] * dirs[:, None, 1] - v[..., 1] * dirs[:, None, 0])
    on = (lateral <= ON_RAY_M) & (along > 0.0)
    meets = on.any(axis=1)
    if not meets.any():
        return False
    surface = np.where(on, along, np.inf).min(axis=1)
    c_along = np.einsum("rk,rk->r", c[None, :] - origins, dirs)
    front = (c_along < surface) & meets
    return bool(np.count_nonzero(front) > 0.5 * np.count_nonzero(meets))
