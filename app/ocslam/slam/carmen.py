"""CARMEN log reader (``*.clf`` / ``*.clf.bz2`` / ``*.log``): front-laser scans with odometry.

- ``FLASER n r_1 … r_n x y theta odom_x odom_y odom_theta ipc_timestamp ipc_hostname logger_timestamp``.
- Beam layout (CARMEN's rule): the first beam at −90° from the heading, spaced 1° for 180/181 beams,
  0.5° for 360/361, 0.25° for 400/401, else the 180° field of view spread evenly over the beams.
- A reading at (or beyond) the log's maximum range means *no return*: it becomes ``inf`` (the
  :class:`~app.ocslam.messages.LaserScan` convention). The maximum is ``PARAM robot_front_laser_max``
  / ``laser_front_laser_max`` / ``robot_frontlaser_max`` when present, else the largest reading of
  the log if it repeats (the sensor's saturation value), else 81.0 m.
- ``T_base_scan`` from the data: every FLASER line carries the laser pose and the robot pose in the
  odometry frame, so ``T_base_scan = T_odom_base⁻¹ ∘ T_odom_laser`` (the median over the log, used when the
  lines agree to a millimetre); else ``PARAM robot_frontlaser_offset`` (metres along the robot's x axis).
- What was inferred (beams, angular increment, field of view, maximum range and where it came from,
  the sensor offset and its source, the odometry source, timestamps stepping back) is in
  :attr:`CarmenLog.inferred`.
- Odometry at each scan's stamp: interpolated from the ``ODOM`` lines when the log has them, else the
  ``odom_*`` pose inside the ``FLASER`` line. Interpolation is between the ``ODOM`` lines just before and
  just after the scan *in the file*, with the time fraction clamped to ``[0, 1]``: some logs (Intel)
  have ipc timestamps that jump back and forth by up to 0.6 s while the file order is the true order,
  and this rule is the plain time interpolation wherever the timestamps are monotonic (ACES).
"""

from __future__ import annotations

import bz2
import gzip
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from app.ocslam.messages import LaserScan
from app.ocslam.se2 import Pose2, between, wrap_angle


class CarmenError(ValueError):
    """A CARMEN log is missing, unreadable or has no usable FLASER lines."""


def beam_layout(n: int) -> tuple[float, float]:
    """``(angle_min, angle_increment)`` in radians for an ``n``-beam CARMEN front laser."""
    if n <= 0:
        raise CarmenError(f"FLASER with {n} readings")
    deg = {180: 1.0, 181: 1.0, 360: 0.5, 361: 0.5, 400: 0.25, 401: 0.25}.get(n)
    inc = math.radians(deg) if deg is not None else math.pi / n
    return -math.pi / 2.0, inc


@dataclass
class CarmenLog:
    """A parsed log: ``stamps`` ``(N,)``, ``ranges`` list of ``(n_i,)`` (``inf`` = no return),
    ``odom`` ``(N, 3)`` ``T_odom_base`` at each scan, ``flaser_odom`` ``(N, 3)`` the pose inside FLASER,
    ``T_base_scan``, ``max_range`` and the ``params`` found."""

    stamps: NDArray[np.float64]
    ranges: list[NDArray[np.float64]]
    odom: NDArray[np.float64]
    flaser_odom: NDArray[np.float64]
    T_base_scan: Pose2
    max_range: float
    params: dict[str, str]
    stamp_strings: list[str]
    flaser_laser: NDArray[np.float64] | None = None  # (N, 3) the laser pose inside FLASER (odometry frame)
    inferred: dict | None = None

    def __len__(self) -> int:
        return len(self.stamps)

    @property
    def duration(self) -> float:
        return float(self.stamps[-1] - self.stamps[0]) if len(self.stamps) > 1 else 0.0

    def scan(self, i: int) -> LaserScan:
        r = self.ranges[i]
        amin, inc = beam_layout(len(r))
        return LaserScan(
            stamp=float(self.stamps[i]),
            angle_min=amin,
            angle_increment=inc,
            range_min=0.0,
            range_max=self.max_range,
            ranges=r,
            frame_id="base_scan",
        )


def _open(path: Path):
    if path.suffix == ".bz2":
        return bz2.open(path, "rt", errors="replace")
    if path.suffix == ".gz":
        return gzip.open(path, "rt", errors="replace")
    return open(path, errors="replace")


_MAX_PARAMS = ("robot_front_laser_max", "laser_front_laser_max", "robot_frontlaser_max")


def read_carmen(path: str | Path) -> CarmenLog:
    """Parse a CARMEN log; malformed lines are skipped. Raises :class:`CarmenError` if nothing is usable."""
    path = Path(path)
    if not path.exists():
        raise CarmenError(f"{path}: no such file")
    params: dict[str, str] = {}
    odom_t: list[float] = []
    odom_p: list[tuple[float, float, float]] = []
    stamps: list[float] = []
    stamp_s: list[str] = []
    ranges: list[NDArray[np.float64]] = []
    fodom: list[tuple[float, float, float]] = []
    flaser: list[tuple[float, float, float]] = []
    prev_odom: list[int] = []  # index of the last ODOM line before each FLASER (-1: none)
    try:
        with _open(path) as fh:
            for line in fh:
                tok = line.split()
                if not tok or tok[0].startswith("#"):
                    continue
                kind = tok[0]
                try:
                    if kind == "PARAM" and len(tok) >= 3:
                        params[tok[1]] = tok[2]
                    elif kind == "ODOM" and len(tok) >= 8:
                        odom_t.append(float(tok[7]))
                        odom_p.append((float(tok[1]), float(tok[2]), float(tok[3])))
                    elif kind == "FLASER" and len(tok) >= 2:
                        n = int(tok[1])
                        if n <= 0 or len(tok) < 2 + n + 7:
                            continue
                        r = np.array(tok[2 : 2 + n], dtype=np.float64)
                        o = 2 + n
                        fodom.append((float(tok[o + 3]), float(tok[o + 4]), float(tok[o + 5])))
                        flaser.append((float(tok[o]), float(tok[o + 1]), float(tok[o + 2])))
                        stamps.append(float(tok[o + 6]))
                        stamp_s.append(tok[o + 6])
                        ranges.append(r)
                        prev_odom.append(len(odom_t) - 1)
                except ValueError:
                    continue
    except (OSError, EOFError) as e:
        raise CarmenError(f"{path}: cannot read ({e})") from e
    if not stamps:
        raise CarmenError(f"{path}: no FLASER lines")
    st = np.array(stamps)
    max_range = None
    max_src = "default 81 m"
    for k in _MAX_PARAMS:
        if k in params:
            try:
                max_range = float(params[k])
                max_src = f"PARAM {k}"
            except ValueError:
                pass
    if max_range is None:
        allr = np.concatenate(ranges)
        top = float(allr.max())
        if np.count_nonzero(allr >= top - 1e-6) > 1:
            max_range, max_src = top, "largest reading (repeats: the sensor's saturation value)"
        else:
            max_range = 81.0
    # readings at the maximum (within a centimetre or so) are "no return"
    out_r = []
    for r in ranges:
        r = r.copy()
        r[r >= max_range - 0.011] = np.inf
        out_r.append(r)
    try:
        offset = float(params.get("robot_frontlaser_offset", "0") or 0.0)
    except ValueError:
        offset = 0.0
    fo = np.array(fodom).reshape(-1, 3)
    fl = np.array(flaser).reshape(-1, 3)
    T_base_scan, off_src = Pose2(offset, 0.0, 0.0), "PARAM robot_frontlaser_offset" if "robot_frontlaser_offset" in params else "none (0)"
    rel = between(fo, fl)
    rel[:, 2] = wrap_angle(rel[:, 2])
    med = np.median(rel, axis=0)
    med = np.where(np.abs(med) < 1e-6, 0.0, med)  # rounding of the logged poses
    spread = np.percentile(np.abs(rel - med), 95, axis=0)
    if spread[0] < 1e-3 and spread[1] < 1e-3 and spread[2] < 1e-3:
        if np.any(np.abs(med) > 1e-6) or "robot_frontlaser_offset" not in params:
            T_base_scan, off_src = Pose2(float(med[0]), float(med[1]), float(med[2])), "FLASER laser pose vs robot pose"
    counts = np.array([len(r) for r in ranges])
    n_common = int(np.bincount(counts).argmax())
    amin, inc = beam_layout(n_common)
    if len(odom_t) >= 1:
        odom = _interpolate_in_file_order(st, np.array(prev_odom), np.array(odom_t), np.array(odom_p))
    else:
        odom = fo.copy()
    return CarmenLog(
        stamps=st,
        ranges=out_r,
        odom=odom,
        flaser_odom=fo,
        T_base_scan=T_base_scan,
        max_range=float(max_range),
        params=params,
        stamp_strings=stamp_s,
        flaser_laser=fl,
        inferred={
            "scans": int(len(st)),
            "beams": n_common,
            "beam_counts": sorted({int(c) for c in counts}),
            "angle_min_deg": math.degrees(amin),
            "angle_increment_deg": math.degrees(inc),
            "fov_deg": math.degrees(inc * (n_common - 1)),
            "max_range_m": float(max_range),
            "max_range_source": max_src,
            "no_return_fraction": float(np.mean(np.concatenate([~np.isfinite(r) for r in out_r]))),
            "T_base_scan": [T_base_scan.x, T_base_scan.y, T_base_scan.yaw],
            "T_base_scan_source": off_src,
            "odometry_source": "ODOM lines (interpolated in file order)" if len(odom_t) else "FLASER odom_* poses",
            "stamps_stepping_back": int(np.count_nonzero(np.diff(st) < 0)),
        },
    )


def _interpolate_in_file_order(
    t: NDArray[np.float64], prev: NDArray[np.int64], odom_t: NDArray[np.float64], odom_p: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Odometry ``(N, 3)`` at scan stamps ``t`` between the ODOM lines ``prev`` and ``prev + 1`` of the file."""
    n = len(odom_t)
    i0 = np.clip(prev, 0, n - 1)
    i1 = np.clip(prev + 1, 0, n - 1)
    dt = odom_t[i1] - odom_t[i0]
    f = np.where(dt > 0, (t - odom_t[i0]) / np.where(dt > 0, dt, 1.0), 0.0)
    f = np.where(prev < 0, 1.0, np.clip(f, 0.0, 1.0))
    p0, p1 = odom_p[i0], odom_p[i1]
    xy = p0[:, :2] + f[:, None] * (p1[:, :2] - p0[:, :2])
    yaw = wrap_angle(p0[:, 2] + f * wrap_angle(p1[:, 2] - p0[:, 2]))
    return np.concatenate([xy, np.asarray(yaw).reshape(-1, 1)], axis=1)
