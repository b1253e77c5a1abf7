"""Trajectory files in the TUM format: ``stamp x y z qx qy qz qw`` per line (planar: z = 0)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray


def format_tum(stamps: NDArray[np.float64], poses: NDArray[np.float64]) -> str:
    """TUM text for ``(N,)`` stamps and ``(N, 3)`` poses."""
    stamps = np.asarray(stamps, np.float64).reshape(-1)
    poses = np.asarray(poses, np.float64).reshape(-1, 3)
    lines = ["# timestamp tx ty tz qx qy qz qw"]
    for t, (x, y, th) in zip(stamps, poses):
        lines.append(f"{t:.6f} {x:.6f} {y:.6f} 0 0 0 {np.sin(th / 2):.9f} {np.cos(th / 2):.9f}")
    return "\n".join(lines) + "\n"


def read_tum(path: str | Path) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Read a TUM file back to ``(N,)`` stamps and ``(N, 3)`` planar poses (yaw from the quaternion)."""
    rows = []
    for line in Path(path).read_text().splitlines():
        tok = line.split()
        if len(tok) < 8 or tok[0].startswith("#"):
            continue
        rows.append([float(v) for v in tok[:8]])
    a = np.array(rows, np.float64).reshape(-1, 8)
    qx, qy, qz, qw = a[:, 4], a[:, 5], a[:, 6], a[:, 7]
    yaw = np.arctan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
    return a[:, 0], np.stack([a[:, 1], a[:, 2], yaw], axis=1)
