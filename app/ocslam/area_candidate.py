"""The object of one bounding area in one frame (improved mode; paper §2.5.3, Algorithm 1 lines 2-4).

The area's islands pass the checks of the *corner problem* (range against the box's bottom edge, box
size against the class's physical size at the island's range, the box reaching down to the island's
row, free space behind the island where a solid object would be); the passing island nearest the
bisector is the object, legged classes gather their legs, and classes that may be below the LIDAR
plane are placed by ground-plane ranging when no island passes. Reasons are counted in the report.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from app.ocslam.camera import CameraModel
from app.ocslam.candidate import Candidate, FrameReport
from app.ocslam.classes import ClassPrior, prior
from app.ocslam.config import ConsciousnessConfig
from app.ocslam.evidence import ObjectEvidence
from app.ocslam.footprint import Footprint, min_area_rect, rect_corners_near
from app.ocslam.footprint_estimate import estimate_footprint
from app.ocslam.island_checks import (
    apparent_width,
    grid_free,
    hidden_by_other_box,
    narrower_than_class,
    see_through,
    top_below_class,
)
from app.ocslam.islands import Island, islands_linkage
from app.ocslam.messages import OccupancyGrid
from app.ocslam.projection import BoundingArea
from app.ocslam.proximity import angle_wrap
from app.ocslam.se2 import Pose2

FloatArray = NDArray[np.float64]


def area_candidate(
    k: int,
    area: BoundingArea,
    pts: FloatArray,
    idx: NDArray[np.int64],
    beam_b: FloatArray,
    beam_r: FloatArray,
    T_map_scan: Pose2,
    T_map_base: Pose2,
    grid: OccupancyGrid | None,
    rep: FrameReport,
    cfg: ConsciousnessConfig,
    cam: CameraModel,
    scan_clusters: tuple[NDArray[np.int64] | None, FloatArray | None],
    other_boxes: FloatArray | None = None,
    scan_pairs: NDArray[np.int64] | None = None,
) -> tuple[Candidate | None, list[Island]]:
    """The object bounding area ``k`` proposes in this frame (``None``: no consistent island, and no
    ground-plane placement), and the area's islands. ``pts``: ``(N, 2)`` scan points (``base_scan``),
    ``idx`` those assigned to the area; ``beam_b``/``beam_r``: every beam about the apex;
    ``other_boxes``: ``(M, 4)`` the frame's other boxes (camera pixels), whose objects may hide this
    one's lower part; ``scan_pairs``: the scan's point pairs within the island threshold
    (:func:`app.ocslam.islands.close_pairs`), to cluster the area's points without a KD-tree of its own."""
    pc = prior(area.label)
    z_lidar = cam.lidar_height
    ray_dir_scan = np.array([np.cos(area.bearing_center), np.sin(area.bearing_center)])
    ray_o = T_map_scan.transform_points(area.apex[None, :])[0]
    ray_d = np.array(
        [
            np.cos(T_map_scan.yaw) * ray_dir_scan[0] - np.sin(T_map_scan.yaw) * ray_dir_scan[1],
            np.sin(T_map_scan.yaw) * ray_dir_scan[0] + np.cos(T_map_scan.yaw) * ray_dir_scan[1],
        ]
    )
    ray_w = 0.0 if (area.truncated["left"] or area.truncated["right"]) else 1.0
    open_side = int(area.truncated["left"]) - int(area.truncated["right"])
    closed_edge = None
    if open_side:
        # the closed edge's half-line and its outward normal (to the right of the right edge, to the
        # left of the left edge), in the object frame
        b_closed = (area.bearing_right if open_side > 0 else area.bearing_left) + T_map_scan.yaw
        closed_edge = np.array([ray_o, [open_side * math.sin(b_closed), -open_side * math.cos(b_closed)]])
    near = area.near_range_m if np.isfinite(area.near_range_m) else math.inf
    base = float(area.near_range_m) if area.bottom_reliable else float("nan")  # where its base begins

    islands: list[Island] = []
    if not pc.below_plane(z_lidar) and len(idx):
        islands = islands_linkage(pts[idx], idx, float(cfg.island_threshold_m), scan_pairs)
        labels, extents = scan_clusters
        if labels is not None and extents is not None:
            for isl in islands:
                lab = labels[isl.indices]
                lab = lab[lab >= 0]
                isl.full_extent = float(extents[lab].max()) if len(lab) else isl.extent
    if pc.below_plane(z_lidar) and len(idx):
        rep.reject("below_lidar_plane_ignored", 1)

    passing: list[tuple[int, float, float]] = []  # (island index, cost, front range)
    behind_ok: list[int] = []  # pass every check except "behind" (leg candidates)
    tol = float(cfg.range_tolerance)
    k_size = 1.0 + float(cfg.size_consistency_tolerance)
    fx, fy = cam.info.fx, cam.info.fy
    x1, y1, x2, y2 = area.box_px
    half = max(area.half_angle, 1e-4)
    uncut_v = not (area.truncated["top"] or area.truncated["bottom"])  # the box's height is its object's
    for i, isl in enumerate(islands):
        b, r = cam.bearing_ranges_scan(isl.points)
        r_front = float(r.min())
        if r_front > cfg.max_object_range_m:
            isl.reason = "out_of_range"
            rep.reject("out_of_range")
            continue
        reason = None
        behind = False
        if isl.physical_extent > pc.max_island:
            isl.reason = "too_big"
            rep.reject("too_big")  # a wall or furniture piece, never a leg of this class
            continue
        if (
            len(isl) <= 2
            and not pc.on_wall
            and isl.physical_extent > isl.extent + 0.15
            and (
                not (area.truncated["left"] or area.truncated["right"])
                or isl.physical_extent > 1.3 * pc.apparent_width_max
            )
        ):
            # a point or two of something larger that the wedge clips (for a box cut by the border,
            # of something larger than the class)
            isl.reason = "sliver"
            rep.reject("sliver")
            continue
        if cfg.corner_check:
            if area.bottom_reliable:
                lo = area.near_range_lo * (1.0 - tol) - 0.05
                hi = (area.near_range_hi * (1.0 + tol) + 0.3) if np.isfinite(area.near_range_hi) else math.inf
                if r_front < lo:
                    reason = "corner_range"
                elif r_front > hi:
                    behind = True
            if reason is None and not area.truncated["bottom"]:
                # the camera sees the island at the LIDAR's height (nothing in front of it at that
                # height, or the LIDAR would not see it): the box must reach down to that row
                pts3 = np.empty((len(isl), 3))
                pts3[:, :2] = cam.T_base_scan_2d.transform_points(isl.points)
                pts3[:, 2] = z_lidar
                uv, depth = cam.project(pts3)
                ok = depth > 0.05
                if np.any(ok) and y2 < float(np.min(uv[ok, 1])) - float(cfg.bottom_margin_px) - 2.0:
                    # ... unless another box covers the island's pixels there: its object may hide the
                    # lower part of this box's object from the camera (chairs in front of a table's legs)
                    if not hidden_by_other_box(uv[ok], other_boxes, float(cfg.bottom_margin_px)):
                        reason = "corner_height"
            if reason is None:
                app_w = (x2 - x1) * r_front / fx
                app_h = (y2 - y1) * r_front / fy
                wmin = max(pc.apparent_width_min, 0.5 * pc.length[0])
                if not (area.truncated["left"] or area.truncated["right"]) and app_w < wmin / k_size:
                    reason = "corner_size"
                elif app_w > pc.apparent_width_max * k_size + 0.1:
                    reason = "size_far"
                elif uncut_v and app_h > pc.height[2] * k_size + 0.1:
                    reason = "size_far"
                elif uncut_v and cfg.box_height_check and app_h < pc.height[0] / k_size:
                    reason = "corner_short"  # the box, at this island's range, is lower than any of its class
                elif cfg.top_edge_check and not area.truncated["top"] and top_below_class(y1, r_front, pc, cam, cfg):
                    reason = "corner_top"  # its top edge, however deep the object, is lower than any of its class
            leg_like = pc.legged and isl.physical_extent <= pc.leg_size_max
            cut = area.truncated["left"] or area.truncated["right"]  # its solid centre is unknown
            if reason is None and pc.solid_fraction > 0.0 and not leg_like and not cut:
                if see_through(area, pc, r_front, beam_b, beam_r):
                    reason = "corner_see_through"
                elif narrower_than_class(b, pc, r_front, beam_b, beam_r):
                    reason = "corner_narrow"
                elif grid_free(area, pc, r_front, T_map_scan, grid, (b, r) if cfg.free_space_behind_surface else None):
                    reason = "corner_free_space"
        if reason is not None:
            isl.reason = reason
            rep.reject(reason)
            continue
        off = area.angular_offsets(isl.points)
        if off.min() <= 0.0 <= off.max():
            ang = 0.0
        else:
            ang = float(min(abs(off.min()), abs(off.max())))
        behind_ok.append(i)
        if behind:
            isl.reason = "behind"
            rep.reject("behind")
            continue
        passing.append((i, ang / half, r_front))

    if passing:
        # nearest the bisector; ties to the nearer island. A legged object's box centre looks
        # between its legs at the background, so for legged classes the range counts more.
        r_min = min(p[2] for p in passing)
        w_range = 2.0 if pc.legged else 0.25
        costs = [c + w_range * (r - r_min) / max(r_min, 0.3) for (_, c, r) in passing]
        best = passing[int(np.argmin(costs))][0]
        off_best = float(area.angular_offsets(islands[best].centroid[None, :])[0])
        group = [best]
        # Principle 30: for a class that may stand on a pedestal, a best island that is by itself a support (one
        # leg-sized island on the centre line of an uncut box much wider than it) is the pedestal alone in this view;
        # the other leg-sized islands in its box (the legs of the stools and chairs round a round table, just
        # outside its top) are not its legs.
        app = apparent_width(islands[best].points, area, cam) if ray_w > 0.0 else float("nan")  # at the best island
        central = (
            cfg.central_support and pc.pedestal and ray_w > 0.0
            and _support([best], islands[best], off_best, half, app, pc) is True
        )
        if cfg.legs and pc.legged and islands[best].physical_extent <= pc.leg_size_max and not central:
            group = _group_legs(best, islands, behind_ok, pc)
            if cfg.point_ownership:
                group = corner_legs(group, islands, float(cfg.leg_corner_m))
        pts_scan = np.vstack([islands[g].points for g in group])
        pts_map = T_map_scan.transform_points(pts_scan)
        if ray_w > 0.0 and len(group) > 1:
            app = apparent_width(pts_scan, area, cam)  # at the group's nearest point
        ev = ObjectEvidence()
        ev.add_points(pts_map)
        ev.add_ray(ray_o, ray_d, ray_w, apparent_width=app, open_side=open_side, base_range=base)  # cut box: a viewpoint only
        support: bool | None = None
        legs = pc.legged and all(islands[g].physical_extent <= pc.leg_size_max for g in group)
        ev.observations, ev.leg_obs = 1, int(legs)
        if pc.legged:
            support = _support(group, islands[best], off_best, half, app, pc,
                               whole=not (cfg.support_whole_boxes and ray_w == 0.0))
            if support:
                ev.support_obs, ev.corner_obs = 1, 0
            elif support is None and cfg.support_whole_boxes:
                ev.support_obs, ev.corner_obs = 0, 0  # a view that cannot tell counts neither for nor against one support
            else:
                ev.support_obs, ev.corner_obs = 0, 1
        fp = estimate_footprint(ev, pc)
        return (
            Candidate(
                area_index=k,
                box_cols=area.columns,
                label=area.label,
                confidence=area.confidence,
                source="lidar_legs" if len(group) > 1 else "lidar_island",
                points=pts_map,
                footprint=fp,
                near_range=near,
                islands=group,
                ray_origin=ray_o,
                ray_dir=ray_d,
                ray_weight=ray_w,
                apparent_width=app,
                base_range=base,
                support=support,
                legs=legs,
                open_side=open_side,
                closed_edge=closed_edge,
            ),
            islands,
        )

    # height: ground-plane ranging from the bottom edge
    if not islands and not pc.below_plane(z_lidar):
        rep.reject("no_points")
    if not (cfg.ground_plane and pc.may_be_below_plane(z_lidar)):
        if islands:
            rep.reject("no_consistent_island")
        return None, islands
    gp = _ground_plane_center(area, pc, beam_b, beam_r, rep, cfg, cam, max_range=float(cfg.ground_plane_max_range_m))
    if gp is None:
        return None, islands
    c_map = T_map_scan.transform_points(gp[None, :])[0]
    rep.ground_plane += 1
    fp = Footprint(c_map, float(np.arctan2(ray_d[1], ray_d[0]) + np.pi / 2), pc.length[1], pc.width[1])
    return (
        Candidate(
            area_index=k,
            box_cols=area.columns,
            label=area.label,
            confidence=area.confidence,
            source="ground_plane",
            points=np.zeros((0, 2)),
            footprint=fp,
            near_range=near,
            ray_origin=ray_o,
            ray_dir=ray_d,
            ray_weight=ray_w,
            ground_center=c_map,
        ),
        islands,
    )

def _support(
    group: list[int], best: Island, off: float, half: float, app: float, pc: ClassPrior, whole: bool = True
) -> bool | None:
    """What one view of a legged object says of a single central support (a pedestal): True for one leg-sized island
    on the box's centre line under a box much wider than it; False for several legs, or one island wider than a leg
    or under a box not much wider; ``None`` (no telling) for one leg-sized island off the centre line or a box of
    unknown width: one leg of a four-legged object whose others are hidden, or a neighbour's leg beside a support
    the LIDAR does not see. ``off``: the island's angular offset from the bisector, ``half`` the box's half-angle
    (rad); ``app``: the box's width at the island's range (m, NaN if unknown). ``whole`` False: the box is cut by the
    image border (``consciousness.support_whole_boxes``): its centre line is unknown and its wedge holds what stands
    beside the object, so it tells nothing either way (``None``)."""
    if not whole:
        return None
    if len(group) != 1 or best.physical_extent > pc.leg_size_max:
        return False
    if not (abs(off) < 0.25 * half and math.isfinite(app)):
        return None
    return app > 3.0 * max(best.extent, 0.05)


def _group_legs(best: int, islands: list[Island], eligible: list[int], pc: ClassPrior) -> list[int]:
    """Legs: add leg-sized islands, nearest first, while the union fits the class's footprint."""
    group = [best]
    pts = islands[best].points
    c0 = islands[best].centroid
    others = [i for i in eligible if i != best and islands[i].physical_extent <= pc.leg_size_max]
    others.sort(key=lambda i: float(np.linalg.norm(islands[i].centroid - c0)))
    for i in others:
        trial = np.vstack([pts, islands[i].points])
        _th, lo, hi = min_area_rect(trial)
        d = hi - lo
        if pc.legs_fit(float(d[0]), float(d[1])):
            group.append(i)
            pts = trial
    return group


def corner_legs(group: list[int], islands: list[Island], corner_m: float) -> list[int]:
    """The shape prior of legged furniture: its legs stand at the corners of its footprint.

    Islands of ``group`` farther than ``corner_m`` from every corner of the group's rectangle (a chair
    leg between two table legs, along the table's edge) are not its legs: the worst is dropped and the
    rectangle refitted until every island stands at a corner (two islands always do). ``corner_m``
    ≤ 0 keeps the group.
    """
    group = list(group)
    if corner_m <= 0.0:
        return group
    while len(group) > 2:
        rect = min_area_rect(np.vstack([islands[g].points for g in group]))
        worst, worst_d = -1, 0.0
        for j, g in enumerate(group):
            dist = float(np.min(rect_corners_near(islands[g].points, rect)[0]))
            if dist > worst_d:
                worst, worst_d = j, dist
        if worst_d <= corner_m:
            break
        del group[worst]
    return group


def _ground_plane_center(
    area: BoundingArea,
    pc: ClassPrior,
    beam_b: FloatArray,
    beam_r: FloatArray,
    rep: FrameReport,
    cfg: ConsciousnessConfig,
    cam: CameraModel,
    max_range: float,
) -> FloatArray | None:
    """The object's centre (LIDAR frame) from its bottom edge, or ``None`` (reason counted)."""
    if not area.bottom_reliable:
        rep.reject("ground_plane_unreliable")
        return None
    near = float(area.near_range_m)
    if near > max_range:
        rep.reject("ground_plane_far")
        return None
    x1, _y1, x2, _y2 = area.box_px
    k_size = 1.0 + float(cfg.size_consistency_tolerance)
    app_w = (x2 - x1) * near / cam.info.fx
    if not (area.truncated["left"] or area.truncated["right"]):
        if app_w < max(pc.apparent_width_min, 0.5 * pc.length[0]) / k_size or app_w > pc.apparent_width_max * k_size + 0.05:
            rep.reject("ground_plane_size")
            return None
    off = angle_wrap(beam_b - area.bearing_center)
    sel = np.abs(off) <= max(0.5 * area.half_angle, np.deg2rad(0.6))
    if np.any(sel):
        blocked = beam_r[sel] < near * (1.0 - float(cfg.range_tolerance)) - 0.05
        if np.mean(blocked) > 0.5:
            rep.reject("ground_plane_occluded")
            return None
    r_c = near + 0.5 * pc.width[1]
    return area.apex + r_c * np.array([np.cos(area.bearing_center), np.sin(area.bearing_center)])
