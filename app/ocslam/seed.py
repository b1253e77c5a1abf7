"""The original implementation's Consciousness node, reproduced where it affects results (spec §1, §2).

Used by :class:`app.ocslam.consciousness.Consciousness` in ``mode: seed`` to show the paper's failure
kinds (legs, corners, drift duplicates) on our own world. Deliberately kept: the odometry frame, no
extrinsics (the LIDAR frame is the camera and robot frame), the seed projection (§1.3), a point in
several areas, buffered islands with their buffer in the size, the island nearest the centre line,
axis-aligned sizes that are never rotated, association in list order with the 0.3 m test, the
pairwise pass with the stale creation-time ``area`` and projection, a deleted object that keeps
absorbing/deleting in the same pass, and frames counted only while the pose changes.
Not kept: the ``.confidence`` AttributeError on an exact projection tie (we keep the higher
detection confidence, as the paper says), and NaN ranges are skipped instead of producing NaN points.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.ocslam.candidate import Candidate, FrameReport
from app.ocslam.footprint import Footprint
from app.ocslam.islands import Island, islands_seed
from app.ocslam.messages import Detections, LaserScan, TrackedObject
from app.ocslam.se2 import Pose2
from app.ocslam.seed_projection import (
    SeedProjection,
    seed_assign_points,
    seed_bounding_areas,
    seed_camera_projection,
    seed_scan_points,
)

FloatArray = NDArray[np.float64]


@dataclass(eq=False)
class SeedObject:
    """The original ``Object``: centre (odom), axis-aligned ``width`` (x) × ``height`` (y), stale ``area``."""

    id: int
    label: str
    center: FloatArray
    width: float
    height: float
    detection_confidence: float
    projection: SeedProjection
    presence: float
    frames: int = 1
    area: float = 0.0
    last_seen: float = 0.0
    points: FloatArray = field(default_factory=lambda: np.zeros((0, 2)), repr=False)

    def distance(self, other: SeedObject) -> float:
        return float(np.hypot(*(self.center - other.center)))

    def collides(self, other: SeedObject) -> bool:
        d = self.distance(other)
        return d < (self.width + other.width) / 2.0 and d < (self.height + other.height) / 2.0

    def update_data(self, other: SeedObject, is_new_frame: bool, weight_old: float, frames_for_presence: int) -> None:
        """Rolling-average centre, sizes only grow; frames and presence only on a new frame (f first)."""
        self.center = weight_old * self.center + (1.0 - weight_old) * other.center
        self.width = max(self.width, other.width)
        self.height = max(self.height, other.height)
        if is_new_frame:
            self.frames = min(self.frames + 1, frames_for_presence)
            self.presence = max(self.presence, other.detection_confidence * self.frames / frames_for_presence)


class SeedConsciousness:
    """The original node's state and per-message update (call :meth:`update` once per YOLO message)."""

    def __init__(self) -> None:
        self.objects: list[SeedObject] = []
        self._next_id = 0
        self._last_pose: Pose2 | None = None
        self.camera = seed_camera_projection()

    def reset(self) -> None:
        self.objects = []
        self._next_id = 0
        self._last_pose = None

    def update(
        self,
        detections: Detections,
        scan: LaserScan,
        T_odom_base: Pose2,
        *,
        stamp: float,
        cfg: Any,
        robot_moved: bool | None = None,
    ) -> dict[str, Any]:
        """One YOLO message. Returns the frame's intermediate results (areas, islands, chosen, counts)."""
        if robot_moved is None:
            robot_moved = self._last_pose is None or tuple(self._last_pose) != tuple(T_odom_base)
        self._last_pose = T_odom_base
        is_new_frame = bool(robot_moved)
        F = int(cfg.frames_for_presence)
        w_old = float(cfg.rolling_average_weight)

        points = seed_scan_points(scan.ranges, scan.angle_min, scan.angle_increment)
        areas = seed_bounding_areas(detections)
        member = seed_assign_points(points, areas)
        islands: list[list[Island]] = []
        chosen: list[int | None] = []
        rejected: dict[str, int] = {}
        new_objs: list[SeedObject] = []
        R = np.array([[np.cos(T_odom_base.yaw), -np.sin(T_odom_base.yaw)], [np.sin(T_odom_base.yaw), np.cos(T_odom_base.yaw)]])
        t = np.array([T_odom_base.x, T_odom_base.y])
        for k, proj in enumerate(areas):
            idx = np.flatnonzero(member[:, k])
            proj.points = points[idx]
            isl = islands_seed(points[idx], idx, float(cfg.island_threshold_m))
            islands.append(isl)
            if not isl:
                chosen.append(None)
                rejected["no_points"] = rejected.get("no_points", 0) + 1
                continue
            centers = np.array([i.bbox_center for i in isl])
            best = int(np.argmin(proj.bisector_distance(centers)))
            chosen.append(best)
            x0, y0, x1, y1 = isl[best].bbox
            det = proj.detection
            assert det is not None
            conf = float(np.floor(det.confidence * 100.0)) / 100.0
            c_odom = R @ centers[best] + t
            w, h = x1 - x0, y1 - y0
            new_objs.append(
                SeedObject(
                    id=-1,
                    label=det.label,
                    center=c_odom,
                    width=w,
                    height=h,
                    detection_confidence=conf,
                    projection=proj,
                    presence=conf / F,
                    frames=1,
                    area=w * h,
                    last_seen=stamp,
                    points=(isl[best].points @ R.T) + t,
                )
            )
        created = updated = 0
        thr = float(cfg.tracking_threshold_m)
        for obj in new_objs:
            for ex in self.objects:
                if ex.label == obj.label and ex.distance(obj) < thr:
                    ex.update_data(obj, is_new_frame, w_old, F)
                    ex.last_seen = stamp
                    updated += 1
                    break
            else:
                obj.id = self._next_id
                self._next_id += 1
                self.objects.append(obj)
                created += 1
        removed = self._pairwise_pass(w_old, F)
        return {
            "points": points,
            "areas": areas,
            "islands": islands,
            "chosen": chosen,
            "rejected": rejected,
            "created": created,
            "updated": updated,
            "removed": removed,
            "new_frame": is_new_frame,
        }

    def _pairwise_pass(self, w_old: float, F: int) -> int:
        """Collisions (spec §1.5 item 3), with the original's quirks."""
        objs: list[SeedObject | None] = list(self.objects)
        cam_near = self.camera.near_midpoint
        n = len(objs)
        for i in range(n):
            a = objs[i]
            if a is None:
                continue
            # the original keeps using ``a`` even after it is deleted below
            for j in range(i + 1, n):
                b = objs[j]
                if b is None or not a.collides(b):
                    continue
                if a.label == b.label:
                    if a.area >= b.area:
                        a.update_data(b, False, w_old, F)
                        objs[j] = None
                    else:
                        b.update_data(a, False, w_old, F)
                        objs[i] = None
                else:
                    da = float(np.linalg.norm(a.projection.near_midpoint - cam_near))
                    db = float(np.linalg.norm(b.projection.near_midpoint - cam_near))
                    if da < db or (da == db and a.detection_confidence >= b.detection_confidence):
                        objs[j] = None
                    else:
                        objs[i] = None
        kept = [o for o in objs if o is not None]
        removed = len(self.objects) - len(kept)
        self.objects = kept
        return removed

    # -- output ----------------------------------------------------------------------------------
    def tracked_objects(self, frame_id: str = "odom") -> list[TrackedObject]:
        out = []
        for o in self.objects:
            x, y = float(o.center[0]), float(o.center[1])
            fp = np.array(
                [[x - o.width / 2, y - o.height / 2], [x + o.width / 2, y - o.height / 2], [x + o.width / 2, y + o.height / 2], [x - o.width / 2, y + o.height / 2]]
            )
            out.append(
                TrackedObject(
                    id=o.id,
                    label=o.label,
                    pose=Pose2(x, y, 0.0),
                    size_x=float(o.width),
                    size_y=float(o.height),
                    size_z=0.5,
                    presence=float(o.presence),
                    detection_confidence=float(o.detection_confidence),
                    frames_seen=int(o.frames),
                    source="lidar_island",
                    frame_id=frame_id,
                    last_seen=float(o.last_seen),
                    footprint=fp,
                )
            )
        return out

    def state_dict(self) -> dict[str, Any]:
        return {
            "next_id": self._next_id,
            "objects": [
                {
                    "id": o.id,
                    "label": o.label,
                    "center": o.center.tolist(),
                    "width": o.width,
                    "height": o.height,
                    "detection_confidence": o.detection_confidence,
                    "projection": o.projection.vertices.tolist(),
                    "presence": o.presence,
                    "frames": o.frames,
                    "area": o.area,
                    "last_seen": o.last_seen,
                }
                for o in self.objects
            ],
        }

    def load_state_dict(self, d: dict[str, Any]) -> None:
        from shapely.geometry import Polygon

        objs = []
        for od in d.get("objects", []):
            verts = np.asarray(od["projection"], dtype=np.float64).reshape(4, 2)
            objs.append(
                SeedObject(
                    id=int(od["id"]),
                    label=str(od["label"]),
                    center=np.asarray(od["center"], dtype=np.float64).reshape(2),
                    width=float(od["width"]),
                    height=float(od["height"]),
                    detection_confidence=float(od["detection_confidence"]),
                    projection=SeedProjection(None, verts, Polygon(verts)),
                    presence=float(od["presence"]),
                    frames=int(od["frames"]),
                    area=float(od["area"]),
                    last_seen=float(od.get("last_seen", 0.0)),
                )
            )
        self.objects = objs
        self._next_id = int(d.get("next_id", max((o.id for o in objs), default=-1) + 1))
        self._last_pose = None


def seed_frame_report(out: dict[str, Any], T_odom_base: Pose2, stamp: float) -> FrameReport:
    """The :class:`~app.ocslam.candidate.FrameReport` of one :meth:`SeedConsciousness.update` result
    ``out`` (its areas, islands and the object each area chose, in ``odom``)."""
    rep = FrameReport(
        stamp=stamp,
        mode="seed",
        frame_id="odom",
        T_frame_scan=T_odom_base,
        points_scan=out["points"],
        camera_bound=seed_camera_projection().polygon,
        areas=out["areas"],
        islands=out["islands"],
        rejected=out["rejected"],
        created=out["created"],
        updated=out["updated"],
        removed=out["removed"],
        new_frame=out["new_frame"],
    )
    for k, best in enumerate(out["chosen"]):
        if best is None:
            rep.chosen.append(None)
            continue
        isl = out["islands"][k][best]
        det = out["areas"][k].detection
        x0, y0, x1, y1 = isl.bbox
        c = T_odom_base.transform_points(np.array([[(x0 + x1) / 2, (y0 + y1) / 2]]))[0]
        rep.chosen.append(
            Candidate(
                area_index=k,
                label=det.label,
                confidence=float(det.confidence),
                source="lidar_island",
                points=T_odom_base.transform_points(isl.points),
                footprint=Footprint(c, 0.0, x1 - x0, y1 - y0),
                near_range=float(np.linalg.norm(out["areas"][k].near_midpoint)),
                islands=[best],
                status="seed",
            )
        )
    return rep
