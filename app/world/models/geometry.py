"""Model geometry: footprint polygons and height ranges (for validation, ground truth and the catalogue table).

Example:
    >>> model_footprint("dog").shape          # (K, 2) convex polygon in the model frame, CCW
    >>> model_z_range("dog")                  # (z_min, z_max) above the floor, metres
"""

from __future__ import annotations

from collections.abc import Iterable
from functools import cache

import numpy as np
from numpy.typing import NDArray

from app.world.models.catalogue import MODELS, get_model
from app.world.models.meshes import part_trimesh

__all__ = ["model_footprint", "model_z_range", "describe"]


@cache
def _footprint_and_z(name: str) -> tuple[NDArray[np.float64], float, float]:
    from shapely import MultiPoint

    spec = get_model(name)
    pts, zs = [], []
    for part in spec.parts:
        m = part_trimesh(part, 1.0)
        pts.append(np.asarray(m.vertices)[:, :2])
        zs.append(np.asarray(m.vertices)[:, 2])
    hull = MultiPoint(np.vstack(pts)).convex_hull
    xy = np.asarray(hull.exterior.coords)[:-1]
    if hull.exterior.is_ccw is False:
        xy = xy[::-1]
    allz = np.concatenate(zs)
    return np.round(xy, 6), float(max(allz.min(), 0.0)), float(allz.max())


def model_footprint(name: str, scale: float = 1.0) -> NDArray[np.float64]:
    """``(K, 2)`` counter-clockwise convex footprint polygon in the model frame (metres)."""
    return _footprint_and_z(name)[0] * scale


def model_z_range(name: str, scale: float = 1.0) -> tuple[float, float]:
    """``(z_min, z_max)`` of the model above the floor."""
    _, z0, z1 = _footprint_and_z(name)
    return z0 * scale, z1 * scale


def describe(names: Iterable[str] | None = None) -> list[dict]:
    """A table of the catalogue (name, class, legged, size, description), for docs and the CLI."""
    rows = []
    for n in names or MODELS:
        spec = get_model(n)
        fp = model_footprint(n)
        z0, z1 = model_z_range(n)
        rows.append(
            {
                "model": n,
                "class": spec.label or "-",
                "legged": spec.legged,
                "size_m": [round(float(np.ptp(fp[:, 0])), 3), round(float(np.ptp(fp[:, 1])), 3), round(z1 - z0, 3)],
                "description": spec.description,
            }
        )
    return rows
