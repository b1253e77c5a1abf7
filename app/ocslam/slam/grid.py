"""Log-odds occupancy grid in the map frame that grows as the robot explores.

The grid keeps the *sum* of every scan's log-odds contribution (each cell at most one hit or one miss
per scan, hits taking precedence) and clamps only when it is read. Sums make a scan's contribution
exactly removable, so after a pose-graph correction a moved keyframe is re-inserted by subtracting
its contribution at the old pose and adding it at the new one, instead of rebuilding the whole map.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from app.ocslam.messages import OccupancyGrid
from app.ocslam.se2 import Pose2
from app.ocslam.slam.raycast import cast_scan


class LogOddsGrid:
    """Axis-aligned, growable log-odds grid.

    Cell ``(row i, col j)`` covers ``origin_xy + ((j, i) + [0, 1)) * resolution`` in the map frame
    (the :class:`~app.ocslam.messages.OccupancyGrid` layout with an unrotated origin).
    """

    def __init__(
        self,
        resolution: float,
        log_odds_hit: float = 0.85,
        log_odds_miss: float = -0.4,
        clamp: float = 5.0,
        grow_margin_m: float = 4.0,
    ) -> None:
        if not resolution > 0:
            raise ValueError("resolution must be > 0")
        self.resolution = float(resolution)
        self.log_odds_hit = float(log_odds_hit)
        self.log_odds_miss = float(log_odds_miss)
        self.clamp = float(clamp)
        self.grow_margin_m = float(grow_margin_m)
        self.origin_xy = np.zeros(2)
        self.log_odds = np.zeros((0, 0), np.float32)  # (H, W) summed log-odds
        self.observed = np.zeros((0, 0), np.int32)  # (H, W) number of scans that touched the cell
        #: bumped by every change of the cells (scan_update, ensure): to_msg reuses its last cells until then
        self.revision = 0
        self._msg_cells: tuple[int, NDArray[np.int8]] | None = None

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.log_odds.shape[0]), int(self.log_odds.shape[1]))

    def to_cells(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """``(N, 2)`` map points → continuous cell coordinates ``(N, 2)`` as ``(u_x, u_y)``."""
        return (np.asarray(points, np.float64).reshape(-1, 2) - self.origin_xy) / self.resolution

    def ensure(self, lo_xy: NDArray[np.float64], hi_xy: NDArray[np.float64]) -> None:
        """Grow the grid (keeping its contents) so it covers the box ``[lo_xy, hi_xy]`` in the map frame."""
        res = self.resolution
        H, W = self.shape
        if H and W:
            cur_lo = self.origin_xy
            cur_hi = self.origin_xy + np.array([W, H]) * res
            if np.all(lo_xy >= cur_lo) and np.all(hi_xy < cur_hi):
                return
            new_lo = np.where(lo_xy < cur_lo, lo_xy - self.grow_margin_m, cur_lo)
            new_hi = np.where(hi_xy >= cur_hi, hi_xy + self.grow_margin_m, cur_hi)
        else:
            new_lo = lo_xy - self.grow_margin_m
            new_hi = hi_xy + self.grow_margin_m
        # snap the new origin to whole cells relative to the old one, so cells keep their positions
        shift = np.ceil((self.origin_xy - new_lo) / res).astype(np.int64) if H and W else np.zeros(2, np.int64)
        origin = self.origin_xy - shift * res if H and W else np.floor(new_lo / res) * res
        nW = int(math.ceil((new_hi[0] - origin[0]) / res)) + 1
        nH = int(math.ceil((new_hi[1] - origin[1]) / res)) + 1
        lo = np.zeros((nH, nW), np.float32)
        ob = np.zeros((nH, nW), np.int32)
        if H and W:
            lo[shift[1] : shift[1] + H, shift[0] : shift[0] + W] = self.log_odds
            ob[shift[1] : shift[1] + H, shift[0] : shift[0] + W] = self.observed
        self.origin_xy = origin
        self.log_odds, self.observed = lo, ob
        self.revision += 1

    def scan_update(
        self, sensor_xy: NDArray[np.float64], ends_xy: NDArray[np.float64], hit: NDArray[np.bool_], sign: float = 1.0
    ) -> None:
        """Add (``sign=+1``) or remove (``sign=-1``) one scan's contribution.

        Args:
            sensor_xy: ``(2,)`` sensor position in the map frame.
            ends_xy: ``(B, 2)`` beam ends in the map frame (returns, or the clearing limit for beams
                without a return).
            hit: ``(B,)`` True for beams that ended on an obstacle.
        """
        ends_xy = np.asarray(ends_xy, np.float64).reshape(-1, 2)
        if len(ends_xy) == 0:
            return
        allp = np.vstack([ends_xy, np.asarray(sensor_xy, np.float64).reshape(1, 2)])
        self.ensure(allp.min(axis=0), allp.max(axis=0))
        u0 = self.to_cells(sensor_xy)[0]
        u = self.to_cells(ends_xy)
        fr, fc, hr, hc = cast_scan(u0, u, hit)
        H, W = self.shape
        n = H * W
        free = np.bincount(fr * W + fc, minlength=n) > 0
        hits = np.bincount(hr * W + hc, minlength=n) > 0 if len(hr) else np.zeros(n, bool)
        free &= ~hits
        lo = self.log_odds.reshape(-1)
        ob = self.observed.reshape(-1)
        fi = np.flatnonzero(free)
        hi = np.flatnonzero(hits)
        lo[fi] += np.float32(sign * self.log_odds_miss)
        lo[hi] += np.float32(sign * self.log_odds_hit)
        step = 1 if sign > 0 else -1
        ob[fi] += step
        ob[hi] += step
        self.revision += 1

    def probability(self) -> NDArray[np.float64]:
        """``(H, W)`` occupancy probability from the clamped log-odds (0.5 where unobserved)."""
        L = np.clip(self.log_odds, -self.clamp, self.clamp).astype(np.float64)
        return 1.0 / (1.0 + np.exp(-L))

    def to_msg(self, stamp: float = 0.0, frame_id: str = "map") -> OccupancyGrid:
        """The grid as :class:`OccupancyGrid` (``-1`` unknown, ``0..100``). Its ``data`` is read-only and
        shared by the messages of one :attr:`revision` (the loop asks for the map at every camera frame)."""
        H, W = self.shape
        if H == 0:
            return OccupancyGrid(self.resolution, Pose2(0.0, 0.0, 0.0), np.full((1, 1), -1, np.int8), stamp, frame_id)
        cached = self._msg_cells
        if cached is not None and cached[0] == self.revision:
            data = cached[1]
        else:
            data = np.rint(self.probability() * 100.0).astype(np.int8)
            data[self.observed <= 0] = -1
            data.flags.writeable = False
            self._msg_cells = (self.revision, data)
        return OccupancyGrid(
            resolution=self.resolution,
            origin=Pose2(float(self.origin_xy[0]), float(self.origin_xy[1]), 0.0),
            data=data,
            stamp=stamp,
            frame_id=frame_id,
        )
