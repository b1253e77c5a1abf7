"""The corner problem's checks on one island as the object of one bounding area (improved mode; paper §2.5.3):
whether its pixels lie in another box, the box's width at its range, whether the LIDAR sees through or past it
where the class would block it, whether the grid knows free space behind it, whether the box's top edge is too
low for the class at its range. Each answers for one island of one box in one frame (``base_scan`` bearings and
ranges about the wedges' apex, ``map`` for the grid)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from app.ocslam.camera import CameraModel
from app.ocslam.classes import ClassPrior
from app.ocslam.config import ConsciousnessConfig
from app.ocslam.footprint import linspace
from app.ocslam.messages import OccupancyGrid
from app.ocslam.projection import BoundingArea
from app.ocslam.proximity import angle_wrap
from app.ocslam.se2 import Pose2

FloatArray = NDArray[np.float64]


def hidden_by_other_box(uv: FloatArray, other_boxes: FloatArray | None, margin_px: float) -> bool:
    """True if most ``(K, 2)`` pixels lie inside one of the other boxes (grown by ``margin_px``)."""
    if other_boxes is None or len(other_boxes) == 0 or len(uv) == 0:
        return False
    b = np.asarray(other_boxes, dtype=np.float64).reshape(-1, 4)
    u, v = uv[:, 0][:, None], uv[:, 1][:, None]
    inside = (u >= b[:, 0] - margin_px) & (u <= b[:, 2] + margin_px) & (v >= b[:, 1] - margin_px) & (v <= b[:, 3] + margin_px)
    return bool(np.mean(inside.any(axis=1)) > 0.5)


def apparent_width(points_scan: FloatArray, area: BoundingArea, cam: CameraModel) -> float:
    """The box's width (m) at the nearest range of ``(N, 2)`` points (``base_scan``) from the camera."""
    _b, r = cam.bearing_ranges_scan(points_scan)
    return 2.0 * float(r.min()) * math.tan(area.half_angle)


def see_through(area: BoundingArea, pc: ClassPrior, r_front: float, beam_b: FloatArray, beam_r: FloatArray) -> bool:
    """True if most beams through the box's solid centre pass far behind ``r_front``."""
    off = angle_wrap(beam_b - area.bearing_center)
    sel = np.abs(off) <= pc.solid_fraction * area.half_angle
    if not np.any(sel):
        return False
    r = beam_r[sel]
    r = r[r >= r_front - 0.1]
    if len(r) < 2:
        return False
    depth = (pc.width[2] + 0.1) if pc.on_wall else (pc.apparent_width_max + 0.1)
    return 2 * int(np.count_nonzero(r > r_front + depth)) > len(r)  # most of them (np.mean > 0.5, in integers)


def narrower_than_class(b: FloatArray, pc: ClassPrior, r_front: float, beam_b: FloatArray, beam_r: FloatArray) -> bool:
    """True if the LIDAR sees past *both* sides of an island where the narrowest instance of a solid class
    would still block it: a stool's or a table's leg in the wedge of a far gnome's or flowers' box.

    ``b``: the island's bearings about the apex. The class's narrowest side (``width[0]``, at least 0.6 of
    its nominal) spans ``±w/2`` about the island's middle bearing at ``r_front``; on each side, the first
    beam past the island within that span must end far behind it (more than the class's largest extent,
    as :func:`see_through`). A nearer return there hides what lies behind it, a return at the island's
    range continues it, and a side with no beam in the span (far objects, coarse beams) cannot tell."""
    if pc.legged or pc.on_wall or pc.solid_fraction <= 0.0 or len(b) == 0 or len(beam_b) == 0:
        return False
    w = max(pc.width[0], 0.6 * pc.width[1])
    mid = float(np.arctan2(np.sin(b).mean(), np.cos(b).mean()))
    off_isl = angle_wrap(b - mid)
    half_isl = float(np.max(np.abs(off_isl)))
    half_obj = 0.5 * w / max(r_front, 0.1)
    if half_isl >= half_obj:
        return False
    off = angle_wrap(beam_b - mid)
    depth = pc.apparent_width_max + 0.1
    for side in (1.0, -1.0):
        o = side * off
        sel = (o > half_isl + 1e-9) & (o <= half_obj)
        if not np.any(sel):
            return False
        first = int(np.flatnonzero(sel)[np.argmin(o[sel])])
        if not beam_r[first] > r_front + depth:  # nearer (hiding) or at its range (continuing); inf: passes
            return False
    return True


def grid_free(
    area: BoundingArea,
    pc: ClassPrior,
    r_front: float,
    T_map_scan: Pose2,
    grid: OccupancyGrid | None,
    surface: tuple[FloatArray, FloatArray] | None = None,
) -> bool:
    """True if the occupancy grid shows known free space just behind the island across the box's solid centre.

    ``surface``: the island's ``(N,)`` bearings and ranges about the apex; along the bearings it covers, "just
    behind" follows its surface (an armchair seen corner first is solid behind both its faces, not beside its
    front corner); elsewhere, and without it, just behind its front range ``r_front``."""
    if grid is None or grid.data.size == 0 or not np.isfinite(grid.resolution) or grid.resolution <= 0:
        return False
    half = pc.solid_fraction * area.half_angle
    b = area.bearing_center + linspace(-half, half, 9)
    r = np.full(9, r_front)
    if surface is not None and len(surface[0]) >= 2:
        sb, sr = surface
        rel = (sb - area.bearing_center + np.pi) % (2.0 * np.pi) - np.pi
        order = np.argsort(rel)
        rel, sr = rel[order], sr[order]
        off = b - area.bearing_center
        on = (off >= rel[0]) & (off <= rel[-1])
        r[on] = np.interp(off[on], rel, sr)
    r = r + max(grid.resolution, 0.05)
    probe = np.empty((9, 2))
    probe[:, 0] = area.apex[0] + r * np.cos(b)
    probe[:, 1] = area.apex[1] + r * np.sin(b)
    cells = grid.world_to_cell(T_map_scan.transform_points(probe))
    rows, cols = cells[:, 0], cells[:, 1]
    inside = (rows >= 0) & (rows < grid.height) & (cols >= 0) & (cols < grid.width)
    v = grid.data[rows[inside], cols[inside]]
    known = v >= 0
    n_known = int(np.count_nonzero(known))
    if n_known < 3:
        return False
    return int(np.count_nonzero(v[known] < 20)) / n_known > 0.6

def top_below_class(y1: float, r_front: float, pc: ClassPrior, cam: CameraModel, cfg: ConsciousnessConfig) -> bool:
    """True if no object of the class can have its image top at row ``y1`` (px, inside the image) with its front at
    ``r_front`` (m, the island's range from the camera).

    Every point of the object lies at or below the ray through ``y1``: at range ``d`` it is at most
    ``h_cam + (c_y − y1)/f_y · d`` high. The point at the top row is the object's highest seen from the camera, the
    nearest part of a flat top above the camera (a table) or a part farther back (a chair's back), but no
    farther than ``r_front`` plus the largest size of the class's shorter side — at ``r_front`` itself for a class
    whose highest point stands above its front (``pc.top_at_front``: a bookcase's or a door's top edge; with
    ``cfg.top_edge_front``); if even there the ray (with ``bottom_margin_px`` of slack on the row) stays below the
    class's lowest instance, the island is not this box's object. Pinhole, level camera."""
    rows_above = cam.info.cy - (y1 - float(cfg.bottom_margin_px))
    depth = 0.0 if (pc.top_at_front and cfg.top_edge_front) else pc.width[2]
    z_top = cam.camera_height + rows_above / cam.info.fy * (r_front + depth)
    return bool(z_top < pc.height[0])
