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
   (``corner_see_through``) and in the occupancy grid (``corner_free_space``), or past both sides of an island
   narrower than any instance of the class (``corner_narrow``).
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

import math
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from shapely.geometry import Polygon

from app.ocslam.association import associate, bearing_match, sighting, wide_box
from app.ocslam.calibration import ScoreCalibration
from app.ocslam.camera import CameraModel
from app.ocslam.candidate import SOURCES, Candidate, FrameReport
from app.ocslam.collisions import resolve_track_collisions
from app.ocslam.config import ConsciousnessConfig
from app.ocslam.frame_candidates import frame_candidates
from app.ocslam.frame_collisions import islands_apart
from app.ocslam.free_space import grid_free_fn
from app.ocslam.ghosts import decay_tracks
from app.ocslam.keyframe_anchors import KeyframeAnchors
from app.ocslam.messages import CLASS_NAMES, Detection, Detections, LaserScan, OccupancyGrid, TrackedObject
from app.ocslam.outside import seen_outside
from app.ocslam.projection import bounding_areas, camera_bound
from app.ocslam.proximity import angle_wrap
from app.ocslam.scan_beams import scan_beams
from app.ocslam.se2 import Pose2
from app.ocslam.seed import SeedConsciousness, seed_frame_report
from app.ocslam.track_state import tracks_from_state, tracks_state
from app.ocslam.tracks import Sighting, Track, create_track, credit_track, export_track, update_track

FloatArray = NDArray[np.float64]

__all__ = ["SOURCES", "Candidate", "Consciousness", "FrameReport", "Sighting", "Track"]

#: The former private names (kept for anyone who imported them).
_Track = Track
_Sighting = Sighting


class Consciousness:
    """The object map. ``cfg`` is read live on every :meth:`update`."""

    def __init__(
        self, cfg: ConsciousnessConfig, camera: CameraModel, score_calibration: ScoreCalibration | None = None
    ) -> None:
        self.cfg = cfg
        self.camera = camera
        #: improved mode: the detector's box score → the probability that the box is right (its model
        #: card's Platt scaling, :mod:`app.ocslam.calibration`); the soft decision reads that probability
        #: as ``Y_c``. Seed mode always reads the raw score, as the paper does. Identity: none.
        self.score_calibration = score_calibration if score_calibration is not None else ScoreCalibration()
        self._seed = SeedConsciousness()
        self._tracks: list[Track] = []
        self._next_id = 0
        self._mode = cfg.mode
        self._anchors = KeyframeAnchors()
        self._last_pose: Pose2 | None = None
        self._last_stamp: float | None = None
        self.last_report: FrameReport | None = None
        self._stamp = -math.inf
        self._known_free: Callable[[FloatArray], NDArray[np.bool_]] | None = None
        self._beams: tuple[tuple[float, float, int], FloatArray, FloatArray, FloatArray] | None = None
        #: tracks moved by a correction since the last frame: re-estimated again at the next frame, with
        #: the occupancy grid built on the corrected poses (the free-space and wall checks need it)
        self._moved: dict[int, Track] = {}

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
        return [export_track(t, self._anchors.poses, self.cfg) for t in self._tracks if t.footprint is not None]

    def visible_objects(self) -> list[TrackedObject]:
        """Objects with presence ≥ ``presence_threshold`` (the published map)."""
        thr = float(self.cfg.presence_threshold)
        return [o for o in self.objects if o.presence >= thr]

    def reset(self) -> None:
        self._seed.reset()
        self._tracks = []
        self._next_id = 0
        self._anchors = KeyframeAnchors()
        self._last_pose = None
        self._last_stamp = None
        self.last_report = None
        self._moved = {}

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
        deltas = self._anchors.correct(keyframe_pose)
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
            "keyframes": {str(k): list(v) for k, v in self._anchors.poses.items()},
            "tracks": tracks_state(self._tracks),
            "seed": self._seed.state_dict(),
        }

    def load_state_dict(self, d: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output; raises ``ValueError`` on a malformed state."""
        try:
            mode = str(d.get("mode", "improved"))
            if mode not in ("seed", "improved"):
                raise ValueError(f"unknown mode {mode!r}")
            tracks = tracks_from_state(d.get("tracks", []))
            kfs = {int(k): Pose2.from_array(v) for k, v in d.get("keyframes", {}).items()}
            seed = SeedConsciousness()
            seed.load_state_dict(d.get("seed", {}))
        except (KeyError, TypeError) as e:
            raise ValueError(f"consciousness state: {e}") from None
        self.reset()
        self._mode = mode
        self.cfg.mode = mode
        self._tracks = tracks
        self._anchors = KeyframeAnchors(kfs)
        self._seed = seed
        self._next_id = int(d.get("next_id", max((t.id for t in tracks), default=-1) + 1))

    @classmethod
    def from_state_dict(cls, d: dict[str, Any], cfg: ConsciousnessConfig, camera: CameraModel) -> Consciousness:
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
        return seed_frame_report(out, T_odom_base, stamp)

    # ------------------------------------------------------------------------------------------
    # improved mode
    # ------------------------------------------------------------------------------------------
    def _beam_angles(self, angle_min: float, increment: float, n: int) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(n,)`` beam angles of a scan and their cosines and sines (cached: a LIDAR's scans share them)."""
        key = (angle_min, increment, n)
        cached = self._beams
        if cached is None or cached[0] != key:
            angles = angle_min + increment * np.arange(n, dtype=np.float64)
            cached = (key, angles, np.cos(angles), np.sin(angles))
            self._beams = cached
        return cached[1], cached[2], cached[3]

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
        cal = self.score_calibration
        if not cal.is_identity and out:
            p = cal.probabilities([b.confidence for b in out])
            out = [replace(b, confidence=float(pk)) for b, pk in zip(out, p)]
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
        kf, deltas = self._anchors.attach(keyframe)
        if deltas:
            self._apply_deltas(deltas)

        if robot_moved is None:
            lp = self._last_pose
            robot_moved = lp is None or lp.distance(T_map_base) > 1e-4 or abs(float(angle_wrap(lp.yaw - T_map_base.yaw))) > 1e-4
        self._last_pose = T_map_base
        self._stamp = stamp
        self._known_free = grid_free_fn(grid, cfg.hidden_behind_own_face, cfg.legs_seen_free) if cfg.corner_check else None
        if self._moved:
            if self._known_free is not None:
                for track in self._tracks:
                    if self._moved.get(track.id) is track:
                        track.refresh(self._known_free)
            self._moved = {}
        dt = 0.0 if self._last_stamp is None else float(np.clip(stamp - self._last_stamp, 0.0, 1.0))
        self._last_stamp = stamp

        # scan: valid points (for islands) and every beam (for free-space / occlusion tests)
        n_beams = len(np.asarray(scan.ranges).reshape(-1))
        angles, cos_a, sin_a = self._beam_angles(float(scan.angle_min), float(scan.angle_increment), n_beams)
        beams = scan_beams(scan, angles, cos_a, sin_a, cam.apex_scan)
        ranges, pts_all = beams.ranges, beams.points
        beam_b_scan, beam_r_scan = beams.bearing_scan, beams.range_scan

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
        candidates = frame_candidates(areas, beams, float(scan.angle_increment), T_map_scan, T_map_base, grid, rep, cfg, cam)

        # association, evidence, presence
        touched: list[Track] = []
        seen_through: list[tuple[Candidate, Track]] = []  # each candidate's track, in candidate order
        for cand in candidates:
            if cand is None or cand.status == "collision":
                continue
            t = associate(cand, self._tracks, self._stamp, cfg, self._known_free)
            if wide_box(cand.box_cols, float(cam.info.width), float(cfg.wide_box_fraction)):
                if t is None:
                    rep.reject("wide_box_new")  # confirms an object seen before, makes none
                    continue
                if cfg.wide_box_whole_only and t.partial_only:
                    rep.reject("wide_box_fragment")  # a fragment's evidence is its cut boxes: a view filled says no more
                    continue
            if t is None and cfg.base_hidden_makes_none and not math.isfinite(areas[cand.area_index].near_range_m):
                rep.reject("base_hidden")  # its base hidden: the island in its wedge may be what hides it
                continue
            if t is None:
                t = create_track(self._next_id, cand, stamp, kf, cfg, self._known_free)
                self._next_id += 1
                self._tracks.append(t)
                rep.created += 1
                cand.status = "created"
            else:
                if not update_track(t, cand, stamp, kf, bool(robot_moved), cfg, self._known_free):
                    rep.reject("shape_inconsistent")
                rep.updated += 1
                cand.status = "updated"
            cand.track_id = t.id
            t.near_range = cand.near_range
            seen_through.append((cand, t))
            if t not in touched:
                touched.append(t)
        if cfg.islands_apart:
            for i, (ca, ta) in enumerate(seen_through):
                for cb, tb in seen_through[i + 1 :]:
                    if ta is not tb and islands_apart(ca, cb):
                        ta.apart.add(tb.id)
                        tb.apart.add(ta.id)
        # negative evidence: points of each object seen now outside the box that saw it (a neighbour's)
        ratio, ray_sigma, width_cap = float(cfg.outside_ratio), float(cfg.ray_centre_sigma_m), float(cfg.box_width_cap)
        behind, legs_extend, far_face = bool(cfg.ray_centre_behind_surface), bool(cfg.legs_extend), bool(cfg.far_face)
        by_views = bool(cfg.stray_by_views)
        for cand, t in seen_through:
            ev = t.evidence
            changed = (ev.outside_ratio != ratio or ev.ray_centre_sigma != ray_sigma or ev.box_width_cap != width_cap
                       or ev.ray_centre_behind_surface != behind or ev.legs_extend != legs_extend or ev.far_face != far_face
                       or ev.stray_by_views != by_views)
            ev.outside_ratio, ev.ray_centre_sigma, ev.box_width_cap = ratio, ray_sigma, width_cap
            ev.ray_centre_behind_surface, ev.legs_extend, ev.far_face, ev.stray_by_views = behind, legs_extend, far_face, by_views
            if ratio > 0.0 and ev.has_points:
                changed |= ev.mark_outside(seen_outside(ev.points, ev.hits, T_map_scan, areas[cand.area_index], cam, ranges,
                                                        float(scan.angle_min), float(scan.angle_increment), max_r))
            if changed:
                t.refresh(self._known_free)
        # boxes that gave no object still see objects: a tracked object of the class in their wedge, at a
        # range their bottom edge allows, is seen again (beyond the LIDAR's range, points rejected...)
        for k, area in enumerate(areas):
            cand = candidates[k]
            if cand is not None and cand.status != "collision":
                continue
            if area.truncated["left"] or area.truncated["right"]:
                continue  # a box cut by the border does not say where its object is
            sight = sighting(area, T_map_scan, stamp, kf, cfg)
            t = bearing_match(sight, self._tracks, stamp, area.near_range_m)
            if t is not None:
                credit_track(t, sight, k, stamp, bool(robot_moved), cfg, self._known_free)
                rep.bearing_only += 1
                if t not in touched:
                    touched.append(t)
        self._tracks = resolve_track_collisions(self._tracks, touched, stamp, cfg, self._known_free, rep)
        if cfg.ghost_decay and dt > 0.0:
            self._tracks = decay_tracks(self._tracks, areas, T_map_base, T_map_scan, beam_b_scan, beam_r_scan, stamp, dt, rep, cfg, cam)
        return rep

    def _apply_deltas(self, deltas: dict[int, Pose2]) -> None:
        """Move every track's evidence with its keyframes; only the tracks with evidence from a moved
        keyframe are re-estimated (the others keep their footprint, and its free-space check). The
        occupancy grid at hand was built on the poses before the correction, so the moved tracks are
        re-estimated from their evidence alone now and again with the next frame's grid. (Now, not when
        first read: the readers of :attr:`objects` on other threads must not re-estimate.)"""
        for t in self._tracks:
            if t.evidence.transform(deltas):
                t.refresh()
                self._moved[t.id] = t
