"""Information (inverse covariance) of a scan-matching estimate, for the pose-graph edges.

The continuous refinement (:func:`app.ocslam.slam.matcher.refine`) returns the Gauss–Newton Hessian
``H_F`` of its point-to-line cost with respect to the pose ``(x, y, yaw)`` of the scan frame ``S`` in the
field frame ``F``. An edge's error lives in the body frame of its end node (see :mod:`.graph`), so the
Hessian is moved there: a body-frame perturbation ``δ`` of the pose changes the world pose by
``G δ`` with ``G = blockdiag(R(yaw), 1)``, hence ``H_S = Gᵀ H_F G``.

The point residuals are not independent (map and range errors are correlated along a wall), so the raw
Hessian overstates the information; it is divided by ``point_sigma²`` (an effective per-point σ) and
then *clamped* in a whitened space: with ``D = diag(σ_xy, σ_xy, σ_yaw)`` the ceiling σs (the stiffest
edge we trust), the eigenvalues of ``D H D`` are clipped to ``[floor, 1]``. In a well-structured scene
every direction hits the ceiling (the edge is the classic fixed-σ edge); along a corridor's axis the
eigenvalue is tiny and only the floor (and the odometry term the mapper adds) remains, so a loop
closure can slide the corridor along its axis instead of bending it.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray


def to_body_frame(hessian_F: NDArray[np.float64], yaw: float) -> NDArray[np.float64]:
    """``(3, 3)`` Hessian w.r.t. the pose in ``F`` → w.r.t. a perturbation in the pose's own frame."""
    c, s = math.cos(yaw), math.sin(yaw)
    G = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return G.T @ np.asarray(hessian_F, np.float64).reshape(3, 3) @ G


def clamp_information(
    info: NDArray[np.float64], sigma_xy_m: float, sigma_yaw_rad: float, floor: float
) -> NDArray[np.float64]:
    """Clip the eigenvalues of the whitened ``D info D`` (``D = diag(σ_xy, σ_xy, σ_yaw)``) to ``[floor, 1]``.

    The result is symmetric positive definite with every direction's σ between the ceiling σs and
    ``1/sqrt(floor)`` times them.
    """
    D = np.array([sigma_xy_m, sigma_xy_m, sigma_yaw_rad], np.float64)
    M = D[:, None] * np.asarray(info, np.float64).reshape(3, 3) * D[None, :]
    M = 0.5 * (M + M.T)
    if not np.all(np.isfinite(M)):
        M = np.zeros((3, 3))
    w, V = np.linalg.eigh(M)
    w = np.clip(w, floor, 1.0)
    M = (V * w) @ V.T
    Di = 1.0 / D
    return Di[:, None] * M * Di[None, :]


def scan_information(
    hessian_F: NDArray[np.float64],
    yaw: float,
    point_sigma_m: float,
    sigma_xy_m: float,
    sigma_yaw_rad: float,
    floor: float,
) -> NDArray[np.float64]:
    """``(3, 3)`` information of a match in the scan's body frame (see the module docstring)."""
    H = to_body_frame(hessian_F, yaw) / (point_sigma_m * point_sigma_m)
    return clamp_information(H, sigma_xy_m, sigma_yaw_rad, floor)


def strip_direction(
    info: NDArray[np.float64], d: NDArray[np.float64], sigma_xy_m: float, sigma_yaw_rad: float, floor: float
) -> NDArray[np.float64]:
    """Remove the information along the translation direction ``d`` ``(2,)`` (then floor it again).

    Used when another pose, displaced along ``d``, matches almost as well (a periodic corridor: doors at
    a regular spacing): the measurement is then trusted across ``d`` and in heading only.
    """
    d = np.asarray(d, np.float64).reshape(2)
    n = float(np.hypot(d[0], d[1]))
    if n < 1e-12:
        return np.asarray(info, np.float64)
    d = d / n
    P = np.eye(3)
    P[:2, :2] -= np.outer(d, d)
    return clamp_information(P.T @ np.asarray(info, np.float64) @ P, sigma_xy_m, sigma_yaw_rad, floor)


def odometry_information(delta: NDArray[np.float64], sigma_xy_per_m: float, sigma_yaw_per_rad: float, sigma_min_xy_m: float = 0.005, sigma_min_yaw_rad: float = 0.002) -> NDArray[np.float64]:
    """``(3, 3)`` diagonal information of a wheel-odometry increment ``delta`` ``(x, y, yaw)``.

    σ grows with the distance and the rotation of the increment (a standard motion model): translation
    ``σ_min + sigma_xy_per_m · d``; rotation ``σ_min + sigma_yaw_per_rad · |Δyaw| + sigma_xy_per_m · d / 1 m``.
    """
    d = float(math.hypot(delta[0], delta[1]))
    a = abs(float(delta[2]))
    sxy = sigma_min_xy_m + sigma_xy_per_m * d
    syaw = sigma_min_yaw_rad + sigma_yaw_per_rad * a + sigma_xy_per_m * d
    return np.diag([1.0 / sxy**2, 1.0 / sxy**2, 1.0 / syaw**2])


def weakest_direction(info: NDArray[np.float64]) -> tuple[float, float, NDArray[np.float64]]:
    """Translational eigen-analysis of an information: ``(σ weakest m, σ strongest m, (2,) unit axis of the weakest)``."""
    w, V = np.linalg.eigh(np.asarray(info, np.float64)[:2, :2])
    w = np.maximum(w, 1e-300)
    return float(1.0 / math.sqrt(w[0])), float(1.0 / math.sqrt(w[1])), V[:, 0]


__all__ = ["to_body_frame", "clamp_information", "scan_information", "strip_direction", "odometry_information", "weakest_direction"]
