"""Class colours (the original's sha256 colours, spec §1.7) and occupancy-grid shading."""

from __future__ import annotations

import hashlib

import numpy as np
from numpy.typing import NDArray

from app.ocslam.messages import CLASS_NAMES


def class_color(label: str) -> tuple[int, int, int]:
    """The first three bytes of sha256(label), as the original's markers (ball → (233, 222, 8))."""
    d = hashlib.sha256(label.encode()).digest()
    return int(d[0]), int(d[1]), int(d[2])


CLASS_COLORS: dict[str, tuple[int, int, int]] = {name: class_color(name) for name in CLASS_NAMES}


def grid_to_rgb(data: NDArray[np.int8]) -> NDArray[np.uint8]:
    """OccupancyGrid values (−1 unknown, 0..100) → ``(H, W, 3)`` uint8, RViz 'map' colour scheme:
    unknown grey, free white, occupied black, in between shaded."""
    d = np.asarray(data)
    v = np.where(d < 0, 205, 254 - (d.astype(np.int32) * 254) // 100).astype(np.uint8)
    return np.repeat(v[..., None], 3, axis=2)
