"""Keyframes (graph nodes with their scans) and the per-scan trajectory anchored on them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from app.ocslam.se2 import compose


class Growable:
    """An append-only ``(N, *shape)`` numpy array with amortised O(1) appends."""

    def __init__(self, shape: tuple[int, ...] = (), dtype=np.float64, capacity: int = 256) -> None:
        self._a = np.zeros((capacity, *shape), dtype)
        self.n = 0

    def append(self, v) -> None:
        if self.n == len(self._a):
            self._a = np.concatenate([self._a, np.zeros_like(self._a)])
        self._a[self.n] = v
        self.n += 1

    @property
    def data(self) -> NDArray:
        """A view of the ``n`` valid rows (writable)."""
        return self._a[: self.n]

    def __len__(self) -> int:
        return self.n

    @staticmethod
    def from_array(a: NDArray) -> Growable:
        a = np.asarray(a)
        g = Growable(a.shape[1:], a.dtype, max(256, len(a)))
        g._a[: len(a)] = a
        g.n = len(a)
        return g


@dataclass
class KeyframeScan:
    """One keyframe's scan, in the keyframe's ``base`` frame.

    ``points``: ``(P, 2)`` valid returns used for matching; ``ends``: ``(B, 2)`` beam ends for the map
    (returns, or the clearing limit for beams without a return); ``hit``: ``(B,)``; ``sensor``: ``(2,)``
    the scanner's position.
    """

    points: NDArray[np.float64]
    ends: NDArray[np.float64]
    hit: NDArray[np.bool_]
    sensor: NDArray[np.float64]


class Keyframes:
    """Keyframe poses ``T_map_kf`` ``(K, 3)`` (optimised in place), stamps and scans."""

    def __init__(self) -> None:
        self.poses = Growable((3,))
        self.stamps = Growable(())
        self.scans: list[KeyframeScan] = []

    def __len__(self) -> int:
        return len(self.scans)

    def add(self, stamp: float, pose: NDArray[np.float64], scan: KeyframeScan) -> int:
        self.poses.append(pose)
        self.stamps.append(stamp)
        self.scans.append(scan)
        return len(self.scans) - 1


class Trajectory:
    """Every processed scan: stamp, the keyframe it is anchored to and its pose relative to it.

    The corrected pose is ``T_map_base = T_map_kf[anchor] ∘ T_kf_base``, so optimising keyframes moves
    every scan with them. Anchor ``-1`` means the pose is absolute (``rel`` is ``T_map_base``).
    """

    def __init__(self) -> None:
        self.stamps = Growable(())
        self.anchor = Growable((), np.int64)
        self.rel = Growable((3,))
        self.odom = Growable((3,))

    def __len__(self) -> int:
        return len(self.stamps)

    def add(self, stamp: float, anchor: int, rel: NDArray[np.float64], odom: NDArray[np.float64]) -> None:
        self.stamps.append(stamp)
        self.anchor.append(anchor)
        self.rel.append(rel)
        self.odom.append(odom)

    def poses(self, kf_poses: NDArray[np.float64]) -> NDArray[np.float64]:
        """``(N, 3)`` corrected ``T_map_base`` of every scan."""
        a = self.anchor.data
        rel = self.rel.data
        out = rel.copy()
        m = a >= 0
        if m.any():
            out[m] = compose(kf_poses[a[m]], rel[m])
        return out
