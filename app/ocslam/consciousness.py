"""The Consciousness node: detections + LIDAR + pose → a tracked map of classified objects.

The paper's Algorithm 1 and soft decision (§2.5), in two modes (``ConsciousnessConfig.mode``):

- ``seed``: the original implementation's behaviour (:mod:`app.ocslam.seed`), for reproducing the
  paper's failure kinds (legs, corners, drift duplicates).
- ``improved`` (default): true camera geometry (:mod:`app.ocslam.projection`), each LIDAR point in one
  area only, objects kept in the SLAM ``map`` frame and anchored to keyframes, and the rules below.

Per frame (improved):

1. Bounding areas: one wedge per box on the LIDAR plane; the camera's view bound.
2. Points → areas (exclusive, by range consistency with each box's bottom edge).
3. Islands per area (single linkage, gap ≤ ``island_threshold_m``).
4. Checks per island (the *corner problem*): its range against the box's bottom edge
   (``corner_range``: in front of where the object meets the floor; ``behind``: background), its
   range against the box's pixel size for the class's physical size (``corner_size``/``size_far``),
   whether the box reaches down to the island's row at the LIDAR's height (``corner_height``), and
   free space where a solid object of the class would have to be, in the current scan
   (``corner_see_through``) and in the occupancy grid (``corner_free_space``).
5. The passing island nearest the bisector (angular distance, ties to the nearer) is the object;
   for legged classes the other leg-sized islands that fit the class's footprint join it (*legs*).
6. No consistent island: classes that can be below the LIDAR plane are placed by ground-plane
   ranging from the box's bottom edge (*height*, ``source="ground_plane"``).
7. Same-frame collisions: same class → one candidate; different classes overlapping → the one whose
   projection is nearer the camera (else the higher confidence).
8. Association with tracked objects of the same class (centre within ``tracking_threshold_m`` or
   inside the object's footprint), evidence accumulated (points, bisector rays), footprint
   re-estimated (:mod:`app.ocslam.footprint`), presence updated (soft decision).
9. Tracked-object collisions: same class overlapping → merged; different classes overlapping →
   the one with more evidence is kept.
10. Ghost decay for objects in view, in range, not occluded and not explained by any box.

``update`` reads the config on every call, so sliders act immediately; switching ``mode`` clears the
map (the two modes keep their objects in different frames).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np
import shapely
from numpy.typing import NDArray
from scipy.spatial import cKDTree
from shapely.geometry import Polygon

from app.ocslam.classes import ClassPrior, prior
from app.ocslam.config import ConsciousnessConfig
from app.ocslam.footprint import NO_KEYFRAME, Footprint, ObjectEvidence, estimate_footprint, min_area_rect
from app.ocslam.islands import Island, cluster_extents, islands_linkage
from app.ocslam.messages import CLASS_NAMES, Detection, Detections, LaserScan, OccupancyGrid, TrackedObject
from app.ocslam.presence import decay_presence, in_camera_view, initial_presence, occluded_by_scan, update_presence
from app.ocslam.projection import (
    BoundingArea,
    CameraModel,
    assign_points,
    bounding_areas,
    camera_bound,
    seed_camera_projection,
)
from app.ocslam.se2 import Pose2
from app.ocslam.seed import SeedConsciousness

FloatArray = NDArray[np.float64]

#: Improved-mode sources of an object's position.
SOURCES = ("lidar_island", "lidar_legs", "ground_plane")


@dataclass(eq=False)
class Candidate:
    """The object proposed by one bounding area in one frame (positions in the object frame)."""

    area_index: int
    label: str
    confidence: float
    source: str
    points: FloatArray  # (K, 2) island points, object frame
    footprint: Footprint | None
    near_range: float  # the area's near range (projection distance from the camera)
    islands: list[int] = field(default_factory=list)
    ray_origin: FloatArray | None = None
    ray_dir: FloatArray | None = None
    ray_weight: float = 0.0
    ground_center: FloatArray | None = None
    apparent_width: float = float("nan")  # the box's width at the island's range (m), NaN if cut by the border
    support: bool | None = None  # legged classes: one small island on the centre line (a pedestal)
    legs: bool = False  # legged classes: every chosen island is leg-sized
    open_side: int = 0  # +1/-1: the box is cut by the image's left/right border only
    track_id: int | None = None
    status: str = "new"  # new | created | updated | collision

    @property
    def center(self) -> FloatArray:
        if self.footprint is not None:
            return self.footprint.center
        if self.ground_center is not None:
            return self.ground_center
        return self.points.mean(axis=0)


@dataclass(eq=False)
class FrameReport:
    """What one update did, for the UI and for tests.

    ``areas`` are :class:`BoundingArea` (improved) or :class:`SeedProjection` (seed), with polygons in
    the LIDAR frame; ``T_frame_scan`` maps them (and ``points_scan``) into the objects' frame.
    ``islands[k]`` are area ``k``'s islands, ``chosen[k]`` its candidate (``None``: nothing chosen).
    ``rejected`` counts islands/boxes by reason.
    """

    stamp: float
    mode: str
    frame_id: str
    T_frame_scan: Pose2
    points_scan: FloatArray
    camera_bound: Polygon
    areas: list[Any] = field(default_factory=list)
    islands: list[list[Island]] = field(default_factory=list)
    chosen: list[Candidate | None] = field(default_factory=list)
    rejected: dict[str, int] = field(default_factory=dict)
    ground_plane: int = 0
    created: int = 0
    updated: int = 0
    merged: int = 0
    removed: int = 0
    decayed: int = 0
    bearing_only: int = 0  # boxes that gave no object but saw a tracked one (presence frames)
    new_frame: bool = True

    def reject(self, reason: str, n: int = 1) -> None:
        self.rejected[reason] = self.rejected.get(reason, 0) + n

    @property
    def area_polygons(self) -> list[Polygon]:
        return [a.polygon for a in self.areas]


@dataclass(eq=False)
class _Track:
    id: int
    label: str
    presence: float
    frames: int
    confidence: float
    source: str
    evidence: ObjectEvidence
    created: float
    last_seen: float
    last_frame_stamp: float
    footprint: Footprint | None = None
    detections: int = 1
    touched_stamp: float = -math.inf
    near_range: float = math.inf  # this frame's projection distance (collision rule)
    complete_views: int = 0  # observations through boxes not cut by the image border
    misses: int = 0  # frames in clear view (in range, not occluded) without a box of its class
    boxes: dict[float, int] = field(default_factory=dict)  # recent frames (stamp → box index) it was seen in

    def saw(self, stamp: float, box: int, keep: int = 256) -> None:
        self.boxes[stamp] = box
        if len(self.boxes) > keep:
            for k in sorted(self.boxes)[: len(self.boxes) - keep]:
                del self.boxes[k]

    @property
    def partial_only(self) -> bool:
        """Only ever seen through boxes cut by the image border: possibly a fragment of a larger object."""
        return self.complete_views == 0

    @property
    def prior(self) -> ClassPrior:
        return prior(self.label)

    def refresh(self, known_free: Callable[[FloatArray], NDArray[np.bool_]] | None = None) -> None:
        fp = estimate_footprint(self.evidence, self.prior, known_free=known_free)
        if fp is not None:
            self.footprint = fp


@dataclass(eq=False)
class _Sighting:
    """A box that gave no object in its frame (beyond the LIDAR's range, or no consistent island):
    its class, its wedge in the object frame and the range its bottom edge allows. A tracked object
    of its class that it holds was seen again (bearing-only association)."""

    label: str
    confidence: float
    stamp: float
    kf: int
    apex: FloatArray
    direction: FloatArray  # the bisector
    half_angle: float
    r_lo: float
    r_hi: float
    weight: float  # bisector ray weight (0: box cut by the image border)
    apparent_width: float = float("nan")

    def holds(self, center: FloatArray, margin: float = 0.02) -> bool:
        v = np.asarray(center, dtype=np.float64) - self.apex
        r = float(np.hypot(v[0], v[1]))
        ang = abs(float(_angle_wrap(np.arctan2(v[1], v[0]) - np.arctan2(self.direction[1], self.direction[0]))))
        return ang <= self.half_angle + margin and self.r_lo <= r <= self.r_hi


def _angle_wrap(a):
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


def _overlap_fraction(a: Footprint, b: Footprint) -> float:
    """Intersection area over the smaller footprint's area."""
    pa, pb = a.polygon, b.polygon
    inter = shapely.area(shapely.intersection(pa, pb))
    small = max(min(pa.area, pb.area), 1e-9)
    return float(inter / small)


def _min_distance(a: FloatArray, b: FloatArray) -> float:
    """Smallest distance between two ``(N, 2)`` / ``(M, 2)`` point sets (inf if either is empty)."""
    if len(a) == 0 or len(b) == 0:
        return math.inf
    return float(cKDTree(b).query(a, k=1)[0].min())


def _contiguous(a: FloatArray, b: FloatArray, pc: ClassPrior, gap_m: float, typical: bool = False) -> bool:
    """True if two point sets lie within ``gap_m`` and together fit one object of the class (one of
    its typical shapes with ``typical``)."""
    if len(a) == 0 or len(b) == 0 or _min_distance(a, b) > gap_m:
        return False
    _th, lo, hi = min_area_rect(np.vstack([a, b]))
    d = hi - lo
    if typical:
        return pc.fits_typical(float(d[0]), float(d[1]), tolerance=0.25)
    return pc.fits(float(d[0]), float(d[1]), tolerance=0.1)


def _grid_free_fn(grid: OccupancyGrid | None) -> Callable[[FloatArray], NDArray[np.bool_]] | None:
    """``(N, 2)`` points (grid frame) → True where the occupancy grid knows free space."""
    if grid is None or grid.data.size == 0 or not np.isfinite(grid.resolution) or grid.resolution <= 0:
        return None

    def free(points: FloatArray) -> NDArray[np.bool_]:
        cells = grid.world_to_cell(points)
        inside = (cells[:, 0] >= 0) & (cells[:, 0] < grid.height) & (cells[:, 1] >= 0) & (cells[:, 1] < grid.width)
        out = np.zeros(len(points), dtype=bool)
        v = grid.data[cells[inside, 0], cells[inside, 1]].astype(np.int64)
        out[inside] = (v >= 0) & (v < 20)
        return out

    return free


def _along_ray_close(origin: FloatArray, a: FloatArray, b: FloatArray, thr: float, rel: float = 0.25) -> bool:
    """True if ``b`` is within ``thr`` of ``a`` across the line of sight from ``origin``, and within
    ``max(thr, rel·range)`` along it (the uncertainty of ground-plane ranging)."""
    v = a - origin
    r = float(np.hypot(v[0], v[1]))
    if r < 1e-6:
        return float(np.hypot(*(b - a))) < thr
    u = v / r
    d = b - a
    along = abs(float(d @ u))
    across = abs(float(d[0] * u[1] - d[1] * u[0]))
    return across < thr and along < max(thr, rel * r)


def _co_observed(a: "_Track", b: "_Track") -> bool:
    """True if two objects were seen in the same frame through different boxes: two instances."""
    common = a.boxes.keys() & b.boxes.keys()
    return any(a.boxes[k] != b.boxes[k] for k in common)


class Consciousness:
    """The object map. ``cfg`` is read live on every :meth:`update`."""

    def __init__(self, cfg: ConsciousnessConfig, camera: CameraModel) -> None:
        self.cfg = cfg
        self.camera = camera
        self._seed = SeedConsciousness()
        self._tracks: list[_Track] = []
        self._next_id = 0
        self._mode = cfg.mode
        self._kf_poses: dict[int, Pose2] = {}
        self._last_pose: Pose2 | None = None
        self._last_stamp: float | None = None
        self.last_report: FrameReport | None = None
        self._scan_clusters: tuple[NDArray[np.int64] | None, FloatArray | None] = (None, None)
        self._stamp = -math.inf
        self._known_free: Callable[[FloatArray], NDArray[np.bool_]] | None = None

    # ------------------------------------------------------------------------------------------
    # public API
    # ------------------------------------------------------------------------------------------
    @property
    def mode(self) -> str:
        return self._mode

    @property
    def frame_id(self) -> str:
        return "odom" if self._mode == "seed" else "map"

    @property
    def objects(self) -> list[TrackedObject]:
        """Every tracked object (any presence), in the objects' frame (``map``; ``odom`` in seed mode)."""
        if self._mode == "seed":
            return self._seed.tracked_objects("odom")
        return [self._export(t) for t in self._tracks if t.footprint is not None]

    def visible_objects(self) -> list[TrackedObject]:
        """Objects with presence ≥ ``presence_threshold`` (the published map)."""
        thr = float(self.cfg.presence_threshold)
        return [o for o in self.objects if o.presence >= thr]

    def reset(self) -> None:
        self._seed.reset()
        self._tracks = []
        self._next_id = 0
        self._kf_poses = {}
        self._last_pose = None
        self._last_stamp = None
        self.last_report = None

    def update(
        self,
        detections: Detections,
        scan: LaserScan,
        T_frame_base: Pose2,
        *,
        stamp: float,
        grid: OccupancyGrid | None = None,
        keyframe: tuple[int, Pose2] | None = None,
        robot_moved: bool | None = None,
    ) -> FrameReport:
        """Process one detector message with the scan and pose synchronised to its image.

        ``T_frame_base``: the robot pose in the objects' frame (``map`` with SLAM; ``odom`` in seed mode).
        ``keyframe``: ``(k, T_map_keyframe)`` the SLAM keyframe the robot is attached to; new evidence is
        anchored to it. ``robot_moved``: whether this is a new viewpoint (``None``: the pose changed since
        the previous update).
        """
        cfg = self.cfg
        if cfg.mode != self._mode:
            self.reset()
            self._mode = cfg.mode
        pose_ok = all(math.isfinite(v) for v in T_frame_base)
        if not pose_ok or not math.isfinite(stamp):
            rep = FrameReport(float(stamp) if math.isfinite(stamp) else 0.0, self._mode, self.frame_id, Pose2(), np.zeros((0, 2)), Polygon())
            rep.reject("bad_pose")
            self.last_report = rep
            return rep
        if self._mode == "seed":
            rep = self._update_seed(detections, scan, T_frame_base, stamp, robot_moved)
        else:
            rep = self._update_improved(detections, scan, T_frame_base, stamp, grid, keyframe, robot_moved)
        self.last_report = rep
        return rep

    def apply_correction(self, keyframe_pose: Callable[[int], Pose2]) -> int:
        """Move every object with its keyframes after a loop closure / graph optimisation.

        ``keyframe_pose(k)`` returns the corrected ``T_map_keyframe`` of keyframe ``k`` (raise
        ``KeyError``/``IndexError`` for unknown ones). Returns the number of keyframes that moved.
        """
        if self._mode == "seed":
            return 0
        deltas: dict[int, Pose2] = {}
        for k, old in list(self._kf_poses.items()):
            try:
                new = keyframe_pose(k)
            except (KeyError, IndexError):
                continue
            if new is None or not all(math.isfinite(v) for v in new):
                continue
            d = new @ old.inverse()
            self._kf_poses[k] = new
            if abs(d.x) > 1e-9 or abs(d.y) > 1e-9 or abs(d.yaw) > 1e-9:
                deltas[k] = d
        if deltas:
            self._apply_deltas(deltas)
        return len(deltas)

    # -- persistence ------------------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        """JSON-compatible state (objects, evidence, keyframe anchors) for save/load session."""
        return {
            "version": 1,
            "mode": self._mode,
            "next_id": self._next_id,
            "keyframes": {str(k): list(v) for k, v in self._kf_poses.items()},
            "tracks": [
                {
                    "id": t.id,
                    "label": t.label,
                    "presence": t.presence,
                    "frames": t.frames,
                    "confidence": t.confidence,
                    "source": t.source,
                    "created": t.created,
                    "last_seen": t.last_seen,
                    "last_frame_stamp": t.last_frame_stamp,
                    "detections": t.detections,
                    "misses": t.misses,
                    "complete_views": t.complete_views,
                    "footprint": None
                    if t.footprint is None
                    else [float(t.footprint.center[0]), float(t.footprint.center[1]), float(t.footprint.yaw),
                          float(t.footprint.size_x), float(t.footprint.size_y)],
                    "evidence": t.evidence.state_dict(),
                }
                for t in self._tracks
            ],
            "seed": self._seed.state_dict(),
        }

    def load_state_dict(self, d: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output; raises ``ValueError`` on a malformed state."""
        try:
            mode = str(d.get("mode", "improved"))
            if mode not in ("seed", "improved"):
                raise ValueError(f"unknown mode {mode!r}")
            tracks = []
            for td in d.get("tracks", []):
                label = str(td["label"])
                if label not in CLASS_NAMES:
                    raise ValueError(f"unknown class {label!r}")
                t = _Track(
                    id=int(td["id"]),
                    label=label,
                    presence=float(td["presence"]),
                    frames=int(td["frames"]),
                    confidence=float(td["confidence"]),
                    source=str(td.get("source", "lidar_island")),
                    evidence=ObjectEvidence.from_state_dict(td["evidence"]),
                    created=float(td.get("created", 0.0)),
                    last_seen=float(td.get("last_seen", 0.0)),
                    last_frame_stamp=float(td.get("last_frame_stamp", 0.0)),
                    detections=int(td.get("detections", 1)),
                    misses=int(td.get("misses", 0)),
                    complete_views=int(td.get("complete_views", 0)),
                )
                fp = td.get("footprint")
                if fp is not None and len(fp) == 5 and all(math.isfinite(float(v)) for v in fp):
                    # as estimated live (with the occupancy grid then at hand)
                    t.footprint = Footprint(np.array([float(fp[0]), float(fp[1])]), float(fp[2]), float(fp[3]), float(fp[4]))
                else:
                    t.refresh()
                tracks.append(t)
            kfs = {int(k): Pose2.from_array(v) for k, v in d.get("keyframes", {}).items()}
            seed = SeedConsciousness()
            seed.load_state_dict(d.get("seed", {}))
        except (KeyError, TypeError) as e:
            raise ValueError(f"consciousness state: {e}") from None
        self.reset()
        self._mode = mode
        self.cfg.mode = mode
        self._tracks = tracks
        self._kf_poses = kfs
        self._seed = seed
        self._next_id = int(d.get("next_id", max((t.id for t in tracks), default=-1) + 1))

    @classmethod
    def from_state_dict(cls, d: dict[str, Any], cfg: ConsciousnessConfig, camera: CameraModel) -> "Consciousness":
        c = cls(cfg, camera)
        c.load_state_dict(d)
        return c

    # ------------------------------------------------------------------------------------------
    # seed mode
    # ------------------------------------------------------------------------------------------
    def _update_seed(
        self, detections: Detections, scan: LaserScan, T_odom_base: Pose2, stamp: float, robot_moved: bool | None
    ) -> FrameReport:
        out = self._seed.update(detections, scan, T_odom_base, stamp=stamp, cfg=self.cfg, robot_moved=robot_moved)
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

    # ------------------------------------------------------------------------------------------
    # improved mode
    # ------------------------------------------------------------------------------------------
    def _valid_boxes(self, detections: Detections, rep: FrameReport) -> list[Detection]:
        out = []
        for b in detections.boxes:
            ok = (
                isinstance(b.class_id, (int, np.integer))
                and 0 <= int(b.class_id) < len(CLASS_NAMES)
                and all(math.isfinite(float(v)) for v in (b.x1, b.y1, b.x2, b.y2, b.confidence))
            )
            if ok:
                out.append(b)
            else:
                rep.reject("bad_box")
        return out

    def _update_improved(
        self,
        detections: Detections,
        scan: LaserScan,
        T_map_base: Pose2,
        stamp: float,
        grid: OccupancyGrid | None,
        keyframe: tuple[int, Pose2] | None,
        robot_moved: bool | None,
    ) -> FrameReport:
        cfg, cam = self.cfg, self.camera
        T_map_scan = T_map_base @ cam.T_base_scan_2d
        max_r = float(cfg.max_object_range_m)

        # keyframe anchor; a known keyframe given with a new pose is a correction for it
        kf = NO_KEYFRAME
        if keyframe is not None:
            k, T_map_kf = int(keyframe[0]), keyframe[1]
            if all(math.isfinite(v) for v in T_map_kf):
                kf = k
                old = self._kf_poses.get(k)
                self._kf_poses[k] = T_map_kf
                if old is not None:
                    d = T_map_kf @ old.inverse()
                    if abs(d.x) > 1e-9 or abs(d.y) > 1e-9 or abs(d.yaw) > 1e-9:
                        self._apply_deltas({k: d})

        if robot_moved is None:
            lp = self._last_pose
            robot_moved = lp is None or lp.distance(T_map_base) > 1e-4 or abs(float(_angle_wrap(lp.yaw - T_map_base.yaw))) > 1e-4
        self._last_pose = T_map_base
        self._stamp = stamp
        self._known_free = _grid_free_fn(grid) if cfg.corner_check else None
        dt = 0.0 if self._last_stamp is None else float(np.clip(stamp - self._last_stamp, 0.0, 1.0))
        self._last_stamp = stamp

        # scan: valid points (for islands) and every beam (for free-space / occlusion tests)
        ranges = np.asarray(scan.ranges, dtype=np.float64).reshape(-1)
        angles = scan.angle_min + scan.angle_increment * np.arange(len(ranges))
        with np.errstate(invalid="ignore"):
            valid = np.isfinite(ranges) & (ranges >= scan.range_min) & (ranges <= scan.range_max)
            no_return = np.isposinf(ranges) | (np.isfinite(ranges) & (ranges > scan.range_max))
        beam_r = np.where(valid, ranges, np.where(no_return, np.inf, np.nan))
        known = ~np.isnan(beam_r)
        beam_b_scan, beam_r_scan = angles[known], beam_r[known]
        pts_all = np.stack([ranges[valid] * np.cos(angles[valid]), ranges[valid] * np.sin(angles[valid])], axis=1)
        # beams about the apex (the wedges' tip)
        far = np.where(np.isfinite(beam_r_scan), beam_r_scan, 1e3)
        ends = np.stack([far * np.cos(beam_b_scan), far * np.sin(beam_b_scan)], axis=1) - cam.apex_scan[None, :]
        beam_b_apex = np.arctan2(ends[:, 1], ends[:, 0])
        beam_r_apex = np.where(np.isfinite(beam_r_scan), np.hypot(ends[:, 0], ends[:, 1]), np.inf)

        rep = FrameReport(
            stamp=stamp,
            mode="improved",
            frame_id="map",
            T_frame_scan=T_map_scan,
            points_scan=pts_all,
            camera_bound=camera_bound(cam, max_r),
            new_frame=bool(robot_moved),
        )
        boxes = self._valid_boxes(detections, rep)
        det_ok = Detections(detections.stamp, detections.image_width, detections.image_height, tuple(boxes))
        areas = bounding_areas(
            det_ok, cam, max_r, float(cfg.bottom_margin_px), float(cfg.edge_margin_px), float(cfg.range_tolerance)
        )
        rep.areas = areas
        if len(areas) < len(boxes):
            rep.reject("bad_box", len(boxes) - len(areas))
        member = assign_points(pts_all, areas, exclusive=True, range_tolerance=float(cfg.range_tolerance))

        # the whole scan's clusters: an island clipped by its area may belong to a wall
        labels, extents = (
            cluster_extents(pts_all, float(cfg.island_threshold_m), np.flatnonzero(valid), float(scan.angle_increment), len(ranges))
            if areas
            else (None, None)
        )
        self._scan_clusters = (labels, extents)
        candidates: list[Candidate | None] = []
        for k, area in enumerate(areas):
            idx = np.flatnonzero(member[:, k])
            area.points = pts_all[idx]
            cand, isl = self._candidate(k, area, pts_all, idx, beam_b_apex, beam_r_apex, T_map_scan, T_map_base, grid, rep)
            rep.islands.append(isl)
            candidates.append(cand)
        self._resolve_frame_collisions(candidates, rep)
        rep.chosen = candidates

        # association, evidence, presence
        touched: list[_Track] = []
        for cand in candidates:
            if cand is None or cand.status == "collision":
                continue
            t = self._associate(cand)
            if t is None:
                t = self._create(cand, stamp, kf)
                rep.created += 1
                cand.status = "created"
            else:
                if not self._update_track(t, cand, stamp, kf, bool(robot_moved)):
                    rep.reject("shape_inconsistent")
                rep.updated += 1
                cand.status = "updated"
            cand.track_id = t.id
            t.near_range = cand.near_range
            if t not in touched:
                touched.append(t)
        # boxes that gave no object still see objects: a tracked object of the class in their wedge, at a
        # range their bottom edge allows, is seen again (beyond the LIDAR's range, points rejected...)
        for k, area in enumerate(areas):
            cand = candidates[k]
            if cand is not None and cand.status != "collision":
                continue
            if area.truncated["left"] or area.truncated["right"]:
                continue  # a box cut by the border does not say where its object is
            sight = self._sighting(area, T_map_scan, stamp, kf)
            t = self._bearing_match(sight, stamp, area.near_range_m)
            if t is not None:
                self._credit(t, sight, k, stamp, bool(robot_moved))
                rep.bearing_only += 1
                if t not in touched:
                    touched.append(t)
        self._resolve_track_collisions(touched, stamp, rep)
        if cfg.ghost_decay and dt > 0.0:
            self._decay(areas, T_map_base, T_map_scan, beam_b_scan, beam_r_scan, stamp, dt, rep)
        return rep

    # -- per-area candidate ---------------------------------------------------------------------
    def _candidate(
        self,
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
    ) -> tuple[Candidate | None, list[Island]]:
        cfg, cam = self.cfg, self.camera
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
        near = area.near_range_m if np.isfinite(area.near_range_m) else math.inf

        islands: list[Island] = []
        if not pc.below_plane(z_lidar) and len(idx):
            islands = islands_linkage(pts[idx], idx, float(cfg.island_threshold_m))
            labels, extents = self._scan_clusters
            if labels is not None:
                for isl in islands:
                    lab = np.unique(labels[isl.indices])
                    isl.full_extent = float(extents[lab[lab >= 0]].max()) if np.any(lab >= 0) else isl.extent
        if pc.below_plane(z_lidar) and len(idx):
            rep.reject("below_lidar_plane_ignored", 1)

        passing: list[tuple[int, float, float]] = []  # (island index, cost, front range)
        behind_ok: list[int] = []  # pass every check except "behind" (leg candidates)
        tol = float(cfg.range_tolerance)
        k_size = 1.0 + float(cfg.size_consistency_tolerance)
        fx, fy = cam.info.fx, cam.info.fy
        x1, y1, x2, y2 = area.box_px
        half = max(area.half_angle, 1e-4)
        for i, isl in enumerate(islands):
            b, r = cam.bearing_ranges_scan(isl.points)
            r_front = float(r.min())
            if r_front > cfg.max_object_range_m:
                rep.reject("out_of_range")
                continue
            reason = None
            behind = False
            if isl.physical_extent > pc.max_island:
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
                    pts3 = np.hstack([cam.T_base_scan_2d.transform_points(isl.points), np.full((len(isl), 1), z_lidar)])
                    uv, depth = cam.project(pts3)
                    ok = depth > 0.05
                    if np.any(ok) and y2 < float(np.min(uv[ok, 1])) - float(cfg.bottom_margin_px) - 2.0:
                        reason = "corner_height"
                if reason is None:
                    app_w = (x2 - x1) * r_front / fx
                    app_h = (y2 - y1) * r_front / fy
                    wmin = max(pc.apparent_width_min, 0.5 * pc.length[0])
                    if not (area.truncated["left"] or area.truncated["right"]) and app_w < wmin / k_size:
                        reason = "corner_size"
                    elif app_w > pc.apparent_width_max * k_size + 0.1:
                        reason = "size_far"
                    elif not (area.truncated["top"] or area.truncated["bottom"]) and app_h > pc.height[2] * k_size + 0.1:
                        reason = "size_far"
                leg_like = pc.legged and isl.physical_extent <= pc.leg_size_max
                cut = area.truncated["left"] or area.truncated["right"]  # its solid centre is unknown
                if reason is None and pc.solid_fraction > 0.0 and not leg_like and not cut:
                    if self._see_through(area, pc, r_front, beam_b, beam_r):
                        reason = "corner_see_through"
                    elif self._grid_free(area, pc, r_front, T_map_scan, grid):
                        reason = "corner_free_space"
            if reason is not None:
                rep.reject(reason)
                continue
            off = area.angular_offsets(isl.points)
            if off.min() <= 0.0 <= off.max():
                ang = 0.0
            else:
                ang = float(min(abs(off.min()), abs(off.max())))
            behind_ok.append(i)
            if behind:
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
            group = [best]
            if cfg.legs and pc.legged and islands[best].physical_extent <= pc.leg_size_max:
                group = self._group_legs(best, islands, behind_ok, pc)
            pts_scan = np.vstack([islands[g].points for g in group])
            pts_map = T_map_scan.transform_points(pts_scan)
            app = float("nan")
            if ray_w > 0.0:
                _b, r_pts = cam.bearing_ranges_scan(pts_scan)
                app = 2.0 * float(r_pts.min()) * math.tan(area.half_angle)
            ev = ObjectEvidence()
            ev.add_points(pts_map)
            ev.add_ray(ray_o, ray_d, ray_w, apparent_width=app, open_side=open_side)  # cut box: a viewpoint only
            support = None
            legs = pc.legged and all(islands[g].physical_extent <= pc.leg_size_max for g in group)
            ev.observations, ev.leg_obs = 1, int(legs)
            if pc.legged:
                off = area.angular_offsets(islands[best].centroid[None, :])[0]
                support = (
                    len(group) == 1
                    and islands[best].physical_extent <= pc.leg_size_max
                    and abs(off) < 0.25 * half
                    and np.isfinite(app)
                    and app > 3.0 * max(islands[best].extent, 0.05)
                )
                ev.support_obs, ev.corner_obs = (1, 0) if support else (0, 1)
            fp = estimate_footprint(ev, pc)
            return (
                Candidate(
                    area_index=k,
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
                    support=support,
                    legs=legs,
                    open_side=open_side,
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
        gp = self._ground_plane_center(area, pc, beam_b, beam_r, rep, max_range=float(cfg.ground_plane_max_range_m))
        if gp is None:
            return None, islands
        c_map = T_map_scan.transform_points(gp[None, :])[0]
        rep.ground_plane += 1
        fp = Footprint(c_map, float(np.arctan2(ray_d[1], ray_d[0]) + np.pi / 2), pc.length[1], pc.width[1])
        return (
            Candidate(
                area_index=k,
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

    def _see_through(self, area: BoundingArea, pc: ClassPrior, r_front: float, beam_b: FloatArray, beam_r: FloatArray) -> bool:
        """True if most beams through the box's solid centre pass far behind ``r_front``."""
        off = _angle_wrap(beam_b - area.bearing_center)
        sel = np.abs(off) <= pc.solid_fraction * area.half_angle
        if not np.any(sel):
            return False
        r = beam_r[sel]
        r = r[r >= r_front - 0.1]
        if len(r) < 2:
            return False
        depth = (pc.width[2] + 0.1) if pc.on_wall else (pc.apparent_width_max + 0.1)
        return bool(np.mean(r > r_front + depth) > 0.5)

    def _grid_free(
        self, area: BoundingArea, pc: ClassPrior, r_front: float, T_map_scan: Pose2, grid: OccupancyGrid | None
    ) -> bool:
        """True if the occupancy grid shows known free space just behind ``r_front`` across the box's solid centre."""
        if grid is None or grid.data.size == 0 or not np.isfinite(grid.resolution) or grid.resolution <= 0:
            return False
        half = pc.solid_fraction * area.half_angle
        b = area.bearing_center + np.linspace(-half, half, 9)
        r = r_front + max(grid.resolution, 0.05)
        probe = area.apex[None, :] + r * np.stack([np.cos(b), np.sin(b)], axis=1)
        cells = grid.world_to_cell(T_map_scan.transform_points(probe))
        inside = (cells[:, 0] >= 0) & (cells[:, 0] < grid.height) & (cells[:, 1] >= 0) & (cells[:, 1] < grid.width)
        if not np.any(inside):
            return False
        v = grid.data[cells[inside, 0], cells[inside, 1]].astype(np.int64)
        known = v >= 0
        if known.sum() < 3:
            return False
        return bool(np.mean((v[known] < 20)) > 0.6)

    def _group_legs(self, best: int, islands: list[Island], eligible: list[int], pc: ClassPrior) -> list[int]:
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

    def _ground_plane_center(
        self, area: BoundingArea, pc: ClassPrior, beam_b: FloatArray, beam_r: FloatArray, rep: FrameReport, max_range: float
    ) -> FloatArray | None:
        """The object's centre (LIDAR frame) from its bottom edge, or ``None`` (reason counted)."""
        cfg, cam = self.cfg, self.camera
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
        off = _angle_wrap(beam_b - area.bearing_center)
        sel = np.abs(off) <= max(0.5 * area.half_angle, np.deg2rad(0.6))
        if np.any(sel):
            blocked = beam_r[sel] < near * (1.0 - float(cfg.range_tolerance)) - 0.05
            if np.mean(blocked) > 0.5:
                rep.reject("ground_plane_occluded")
                return None
        r_c = near + 0.5 * pc.width[1]
        return area.apex + r_c * np.array([np.cos(area.bearing_center), np.sin(area.bearing_center)])

    # -- same-frame collisions ------------------------------------------------------------------
    def _resolve_frame_collisions(self, cands: list[Candidate | None], rep: FrameReport) -> None:
        thr = float(self.cfg.tracking_threshold_m)
        ov = float(self.cfg.overlap_fraction)
        live = [c for c in cands if c is not None and c.footprint is not None]
        for i, a in enumerate(live):
            for b in live[i + 1 :]:
                if a.status == "collision" or b.status == "collision":
                    continue
                d = float(np.linalg.norm(a.center - b.center))
                frac = _overlap_fraction(a.footprint, b.footprint)  # type: ignore[arg-type]
                if a.label == b.label:
                    if d < thr or frac >= ov:
                        # one object seen through two boxes: a absorbs b
                        a.points = np.vstack([a.points, b.points])
                        a.confidence = max(a.confidence, b.confidence)
                        if len(a.points):
                            ev = ObjectEvidence()
                            ev.add_points(a.points)
                            if a.ray_origin is not None:
                                ev.add_ray(a.ray_origin, a.ray_dir, max(a.ray_weight, 0.2), apparent_width=a.apparent_width)
                            a.footprint = estimate_footprint(ev, prior(a.label)) or a.footprint
                        b.status = "collision"
                        rep.reject("merged_in_frame")
                elif frac >= max(ov, 0.5) or d < 0.5 * thr:
                    if abs(a.near_range - b.near_range) > 1e-6:
                        loser = b if a.near_range < b.near_range else a
                    else:
                        loser = b if a.confidence >= b.confidence else a
                    loser.status = "collision"
                    rep.reject("collision")

    # -- tracks ---------------------------------------------------------------------------------
    def _associate(self, cand: Candidate) -> _Track | None:
        thr = float(self.cfg.tracking_threshold_m)
        best, best_d = None, math.inf
        c = cand.center
        partial = cand.ray_weight == 0.0
        for t in self._tracks:
            if t.label != cand.label or t.footprint is None:
                continue
            if t.boxes.get(self._stamp, cand.area_index) != cand.area_index:
                continue  # already seen in this frame through another box: another instance
            d = float(np.linalg.norm(t.footprint.center - c))
            match = d < thr or bool(t.footprint.contains(c[None, :], margin=0.5 * thr)[0])
            if not match and len(cand.points):
                match = float(np.mean(t.footprint.contains(cand.points, margin=0.5 * thr))) >= 0.5
            if not match and cand.footprint is not None:
                match = bool(cand.footprint.contains(t.footprint.center[None, :])[0])
            if not match and (cand.source == "ground_plane" or not t.evidence.has_points) and cand.ray_origin is not None:
                # ground-plane ranging is uncertain along the line of sight (a few pixels of the bottom
                # edge), not across it
                match = _along_ray_close(cand.ray_origin, cand.center, t.footprint.center, thr)
            if not match and (partial or t.partial_only) and len(cand.points):
                # a partial view of a large object: its points continue the object's (one of its
                # typical shapes holds both)
                match = _contiguous(cand.points, t.evidence.points, t.prior, t.prior.length[2], typical=True)
                if match:
                    d = thr + float(_min_distance(cand.points, t.evidence.points))
            if match and d < best_d:
                best, best_d = t, d
        return best

    def _sighting(self, area: BoundingArea, T_map_scan: Pose2, stamp: float, kf: int) -> _Sighting:
        cfg = self.cfg
        pc = prior(area.label)
        tol = float(cfg.range_tolerance)
        apex = T_map_scan.transform_points(area.apex[None, :])[0]
        b = area.bearing_center + T_map_scan.yaw
        if area.bottom_reliable:
            r_lo = max(area.near_range_lo * (1.0 - tol) - 0.3, 0.0)
            hi = area.near_range_hi if np.isfinite(area.near_range_hi) else 3.0 * area.near_range_m
            r_hi = hi * (1.0 + tol) + pc.length[2]
        else:
            r_lo, r_hi = 0.0, 12.0
        cut = area.truncated["left"] or area.truncated["right"]
        return _Sighting(
            area.label, area.confidence, stamp, kf, apex, np.array([np.cos(b), np.sin(b)]), area.half_angle,
            r_lo, r_hi, 0.0 if cut else 1.0,
        )

    def _bearing_match(self, sight: _Sighting, stamp: float, near: float) -> _Track | None:
        """The tracked object of the sighting's class in its wedge: nearest the range its bottom edge
        gives (relative), then nearest its bisector."""
        best, best_cost = None, math.inf
        for t in self._tracks:
            if t.label != sight.label or t.footprint is None or t.touched_stamp == stamp:
                continue
            # only objects the LIDAR has confirmed (seen whole at least once, with points twice)
            if t.partial_only or (t.evidence.has_points and t.evidence.observations < 2):
                continue
            if not sight.holds(t.footprint.center):
                continue
            v = t.footprint.center - sight.apex
            off = abs(float(_angle_wrap(np.arctan2(v[1], v[0]) - np.arctan2(sight.direction[1], sight.direction[0]))))
            r_front = max(float(np.hypot(v[0], v[1])) - 0.5 * min(t.footprint.size_x, t.footprint.size_y), 0.0)
            dr = abs(r_front - near) / max(near, 0.5) if math.isfinite(near) else 0.0
            cost = dr + off / max(sight.half_angle, 1e-3)
            if cost < best_cost:
                best, best_cost = t, cost
        return best

    def _credit(self, t: _Track, sight: _Sighting, box: int, stamp: float, robot_moved: bool) -> None:
        """A box that saw ``t`` without giving points: a presence frame and a bisector ray."""
        new_frame = robot_moved or (stamp - t.last_frame_stamp >= float(self.cfg.stationary_frame_s) > 0.0)
        if new_frame and t.touched_stamp != stamp:
            t.presence, t.frames = update_presence(t.presence, t.frames, sight.confidence, self.cfg.frames_for_presence)
            t.last_frame_stamp = stamp
        t.evidence.add_ray(sight.apex, sight.direction, sight.weight, sight.kf, decay=float(self.cfg.rolling_average_weight))
        t.touched_stamp = stamp
        t.saw(stamp, box)
        t.detections += 1
        t.last_seen = max(t.last_seen, stamp)
        t.refresh(self._known_free)

    def _create(self, cand: Candidate, stamp: float, kf: int) -> _Track:
        ev = ObjectEvidence()
        self._add_evidence(ev, cand, kf)
        t = _Track(
            id=self._next_id,
            label=cand.label,
            presence=initial_presence(cand.confidence, self.cfg.frames_for_presence),
            frames=1,
            confidence=cand.confidence,
            source=cand.source,
            evidence=ev,
            created=stamp,
            last_seen=stamp,
            last_frame_stamp=stamp,
            touched_stamp=stamp,
        )
        self._next_id += 1
        t.saw(stamp, cand.area_index)
        t.complete_views = int(cand.ray_weight > 0.0)
        t.refresh(self._known_free)
        if t.footprint is None:
            t.footprint = cand.footprint
        self._tracks.append(t)
        return t

    def _add_evidence(self, ev: ObjectEvidence, cand: Candidate, kf: int) -> None:
        w = float(self.cfg.rolling_average_weight)
        if len(cand.points):
            ev.add_points(cand.points, kf)
            ev.observations += 1
            ev.leg_obs += int(cand.legs)
            if cand.support is True:
                ev.support_obs += 1
            elif cand.support is False:
                ev.corner_obs += 1
        if cand.ground_center is not None:
            ev.add_ground_center(cand.ground_center, w, kf)
        if cand.ray_origin is not None and cand.ray_dir is not None:
            ev.add_ray(
                cand.ray_origin, cand.ray_dir, cand.ray_weight, kf, decay=w, apparent_width=cand.apparent_width, open_side=cand.open_side
            )

    def _update_track(self, t: _Track, cand: Candidate, stamp: float, kf: int, robot_moved: bool) -> bool:
        """Add a candidate's evidence to a track; False if its points were left out (shape inconsistent)."""
        pc = t.prior
        consistent = True
        if len(cand.points) and t.evidence.has_points:
            _th, lo, hi = min_area_rect(np.vstack([t.evidence.points, cand.points]))
            d = hi - lo
            if not pc.fits_typical(float(d[0]), float(d[1]), tolerance=0.25):
                # the union would not fit one object of this class: keep the track's shape, use the ray only
                cand = dataclasses.replace(cand, points=np.zeros((0, 2)), ground_center=None)
                consistent = False
        self._add_evidence(t.evidence, cand, kf)
        if cand.source == "lidar_legs" or (cand.source == "lidar_island" and t.source == "ground_plane"):
            t.source = cand.source
        new_frame = robot_moved or (stamp - t.last_frame_stamp >= float(self.cfg.stationary_frame_s) > 0.0)
        if new_frame and t.touched_stamp != stamp:
            t.presence, t.frames = update_presence(t.presence, t.frames, cand.confidence, self.cfg.frames_for_presence)
            t.last_frame_stamp = stamp
        t.touched_stamp = stamp
        t.saw(stamp, cand.area_index)
        t.confidence = cand.confidence
        t.detections += 1
        t.complete_views += int(cand.ray_weight > 0.0)
        t.last_seen = stamp
        t.refresh(self._known_free)
        return consistent

    def _resolve_track_collisions(self, touched: list[_Track], stamp: float, rep: FrameReport) -> None:
        thr = float(self.cfg.tracking_threshold_m)
        ov = float(self.cfg.overlap_fraction)
        removed: set[int] = set()
        for a in touched:
            if a.id in removed or a.footprint is None:
                continue
            for b in list(self._tracks):
                if b is a or b.id in removed or b.footprint is None:
                    continue
                d = float(np.linalg.norm(a.footprint.center - b.footprint.center))
                reach = 0.5 * (np.hypot(a.footprint.size_x, a.footprint.size_y) + np.hypot(b.footprint.size_x, b.footprint.size_y))
                if d > reach + thr:
                    continue
                frac = _overlap_fraction(a.footprint, b.footprint)
                if a.label == b.label:
                    same = d < thr or frac >= ov
                    if not same:
                        # pieces of one object seen from different sides or only in parts (cut by the
                        # image border): close (touching; within the class's length for partial views)
                        # and together one object of the class
                        gap = a.prior.length[2] if (a.partial_only or b.partial_only) else thr
                        same = _contiguous(a.evidence.points, b.evidence.points, a.prior, gap, typical=True)
                    if not same and (not a.evidence.has_points or not b.evidence.has_points):
                        gp, other = (a, b) if not a.evidence.has_points else (b, a)
                        if len(gp.evidence.ray_origin):
                            same = _along_ray_close(gp.evidence.ray_origin[-1], gp.footprint.center, other.footprint.center, thr)
                    if same and _co_observed(a, b):
                        same = False  # seen side by side through two boxes in one frame: two objects
                    if same:
                        keep, drop = (a, b) if (a.presence, a.frames, a.detections) >= (b.presence, b.frames, b.detections) else (b, a)
                        self._merge_tracks(keep, drop)
                        removed.add(drop.id)
                        rep.merged += 1
                        if drop is a:
                            break
                elif frac >= max(ov, 0.5):
                    both_now = a.touched_stamp == stamp and b.touched_stamp == stamp
                    if both_now and abs(a.near_range - b.near_range) > 1e-6:
                        drop = b if a.near_range < b.near_range else a
                    else:
                        # more evidence wins; on a tie the incumbent (older) object stays
                        ka = (a.presence, a.frames, a.detections, -a.created)
                        kb = (b.presence, b.frames, b.detections, -b.created)
                        drop = b if ka >= kb else a
                    removed.add(drop.id)
                    rep.removed += 1
                    if drop is a:
                        break
        if removed:
            self._tracks = [t for t in self._tracks if t.id not in removed]

    def _merge_tracks(self, keep: _Track, drop: _Track) -> None:
        """``keep`` absorbs ``drop`` (same object): evidence united, frames added (they were seen in
        different frames), presence re-evaluated with the soft decision."""
        F = max(int(self.cfg.frames_for_presence), 1)
        keep.evidence.absorb(drop.evidence)
        frames = min(F, keep.frames + drop.frames)
        conf = min(keep.confidence, drop.confidence)
        keep.presence = max(keep.presence, drop.presence, min(conf, 1.0) * frames / F)
        keep.frames = frames
        keep.detections += drop.detections
        keep.complete_views += drop.complete_views
        keep.misses += drop.misses
        for k, v in drop.boxes.items():
            keep.boxes.setdefault(k, v)
        keep.last_seen = max(keep.last_seen, drop.last_seen)
        keep.last_frame_stamp = max(keep.last_frame_stamp, drop.last_frame_stamp)
        keep.created = min(keep.created, drop.created)
        keep.refresh(self._known_free)

    def _decay(
        self,
        areas: Sequence[BoundingArea],
        T_map_base: Pose2,
        T_map_scan: Pose2,
        beam_b_scan: FloatArray,
        beam_r_scan: FloatArray,
        stamp: float,
        dt: float,
        rep: FrameReport,
    ) -> None:
        cfg, cam = self.cfg, self.camera
        T_scan_map = T_map_scan.inverse()
        keep = []
        for t in self._tracks:
            fp = t.footprint
            if fp is None or t.touched_stamp == stamp:
                keep.append(t)
                continue
            # explained by a box of its class whose wedge holds it
            c_scan = T_scan_map.transform_points(fp.center[None, :])
            b, _r = cam.bearing_ranges_scan(c_scan)
            explained = any(a.label == t.label and bool(a.contains_bearing(b, margin=0.05)[0]) for a in areas)
            if explained:
                keep.append(t)
                continue
            if not in_camera_view(fp, t.prior.height[1], T_map_base, cam, float(cfg.decay_max_range_m)):
                keep.append(t)
                continue
            if occluded_by_scan(fp, T_map_scan, beam_b_scan, beam_r_scan, float(cfg.occlusion_margin_m)):
                keep.append(t)
                continue
            # a clear miss. Detectors miss real objects now and then (and the camera may be blocked above
            # the LIDAR's plane), so only an object missed more often than it was detected decays.
            t.misses += 1
            if t.misses <= t.detections:
                keep.append(t)
                continue
            t.presence = decay_presence(t.presence, float(cfg.decay_rate_per_s), dt)
            rep.decayed += 1
            if t.presence > 0.0:
                keep.append(t)
            else:
                rep.removed += 1
        self._tracks = keep

    def _apply_deltas(self, deltas: dict[int, Pose2]) -> None:
        for t in self._tracks:
            t.evidence.transform(deltas)
            t.refresh()


    def _export(self, t: _Track) -> TrackedObject:
        fp = t.footprint
        assert fp is not None
        pose = Pose2(float(fp.center[0]), float(fp.center[1]), float(_angle_wrap(fp.yaw)))
        kf = t.evidence.latest_keyframe()
        anchor = kf if kf != NO_KEYFRAME and kf in self._kf_poses else None
        T_kf_obj = self._kf_poses[anchor].inverse() @ pose if anchor is not None else None
        return TrackedObject(
            id=t.id,
            label=t.label,
            pose=pose,
            size_x=float(fp.size_x),
            size_y=float(fp.size_y),
            size_z=float(t.prior.height[1]),
            presence=float(t.presence),
            detection_confidence=float(t.confidence),
            frames_seen=int(t.frames),
            source=t.source,
            frame_id="map",
            anchor_keyframe=anchor,
            T_keyframe_object=T_kf_obj,
            last_seen=float(t.last_seen),
            footprint=fp.corners,
        )
