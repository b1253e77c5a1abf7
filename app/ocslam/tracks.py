"""Tracked objects (improved mode): the record of one object, its evidence and its soft decision.

A :class:`Track` holds an object's :class:`~app.ocslam.evidence.ObjectEvidence` (points, bisector
rays, ground-plane centres, all in the ``map`` frame), its presence confidence (paper §2.5.4) and the
frames and boxes it was seen in. :func:`create_track`, :func:`update_track`, :func:`credit_track`
and :func:`merge_tracks` are the only ways evidence enters a track; :func:`export_track` turns it into
the published :class:`~app.ocslam.messages.TrackedObject`.

The geometric predicates the association and the collision rules share are in :mod:`app.ocslam.proximity`, what the
grid knows of places in :mod:`app.ocslam.free_space`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from app.ocslam.candidate import Candidate
from app.ocslam.classes import ClassPrior, prior
from app.ocslam.config import ConsciousnessConfig
from app.ocslam.evidence import NO_KEYFRAME, ObjectEvidence
from app.ocslam.footprint import Footprint, min_area_rect, nearest_distances
from app.ocslam.footprint_estimate import estimate_footprint
from app.ocslam.free_space import FreeFn
from app.ocslam.messages import TrackedObject
from app.ocslam.presence import evidence_presence, initial_presence, update_presence
from app.ocslam.proximity import angle_wrap
from app.ocslam.se2 import Pose2

FloatArray = NDArray[np.float64]


#: how many recent frames a track remembers the boxes and the clear misses of
RECENT_FRAMES = 256


@dataclass(eq=False)
class Track:
    """One tracked object (``map`` frame)."""

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
    miss_stamps: set[float] = field(default_factory=set)  # the stamps of those frames (recent ones)
    boxes: dict[float, int] = field(default_factory=dict)  # recent frames (stamp → box index) it was seen in
    box_cols: dict[float, tuple[float, float]] = field(default_factory=dict)  # their boxes' columns (x1, x2), px
    conf_sum: float = 0.0  # confidences of the frames that counted (presence_confidence = mean / best)
    conf_n: int = 0
    conf_best: float = 0.0
    #: objects of its class seen in one frame with it through another box, on an island apart from its own
    #: (:func:`~app.ocslam.frame_collisions.islands_apart`): two instances, however their accumulated points mix
    apart: set[int] = field(default_factory=set)

    def frame_confidence(self, c: float, cfg: ConsciousnessConfig) -> float:
        """``Y_c`` of the soft decision for a new frame with box confidence ``c``: the box's own
        (``latest``, the paper), the mean over the object's counted frames, or the best of them."""
        self.conf_sum += float(c)
        self.conf_n += 1
        self.conf_best = max(self.conf_best, float(c))
        mode = str(getattr(cfg, "presence_confidence", "latest"))
        if mode == "mean":
            return self.conf_sum / self.conf_n
        if mode == "best":
            return self.conf_best
        return float(c)

    def saw(self, stamp: float, box: int, cols: tuple[float, float] | None = None, keep: int = RECENT_FRAMES) -> None:
        """Seen at ``stamp`` through the frame's box ``box`` (its image columns ``cols``, if known)."""
        self.boxes[stamp] = box
        if cols is not None:
            self.box_cols[stamp] = cols
        if len(self.boxes) > keep:
            for k in sorted(self.boxes)[: len(self.boxes) - keep]:
                del self.boxes[k]
                self.box_cols.pop(k, None)

    def missed(self, stamp: float, keep: int = RECENT_FRAMES) -> None:
        """A clear miss at ``stamp`` (its stamp remembered as long as :meth:`saw` remembers boxes)."""
        self.misses += 1
        self.miss_stamps.add(stamp)
        if len(self.miss_stamps) > keep:
            self.miss_stamps.discard(min(self.miss_stamps))

    @property
    def partial_only(self) -> bool:
        """Only ever seen through boxes cut by the image border: possibly a fragment of a larger object."""
        return self.complete_views == 0

    @property
    def prior(self) -> ClassPrior:
        return prior(self.label)

    def refresh(self, known_free: FreeFn | None = None) -> None:
        fp = estimate_footprint(self.evidence, self.prior, known_free=known_free)
        if fp is not None:
            self.footprint = fp


@dataclass(eq=False)
class Sighting:
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
    box_cols: tuple[float, float] | None = None  # the box's image columns (x1, x2), camera pixels

    def holds(self, center: FloatArray, margin: float = 0.02) -> bool:
        v = np.asarray(center, dtype=np.float64) - self.apex
        r = float(np.hypot(v[0], v[1]))
        ang = abs(float(angle_wrap(np.arctan2(v[1], v[0]) - np.arctan2(self.direction[1], self.direction[0]))))
        return ang <= self.half_angle + margin and self.r_lo <= r <= self.r_hi


def co_observed(a: Track, b: Track) -> bool:
    """True if two objects were seen in the same frame through different boxes: two instances."""
    common = a.boxes.keys() & b.boxes.keys()
    return any(a.boxes[k] != b.boxes[k] for k in common)


def pedestal(ev: ObjectEvidence, own: FloatArray, pc: ClassPrior, fraction: float, told_only: bool = False) -> bool:
    """True if a legged object was seen as one small island on its box's centre line in at least ``fraction``
    of its views (and more often than as legs off it), and its points ``own`` ``(N, 2)`` are still that one
    support: a pedestal (a round table's). A four-legged table shows one central leg only from some
    directions; a pedestal stays central from all of them. ``told_only``: the share is of the views that told
    (``support_obs + corner_obs``), not of every view with points (``consciousness.support_whole_boxes``)."""
    if fraction <= 0.0 or not (pc.legged and pc.pedestal) or ev.support_obs <= ev.corner_obs or len(own) == 0:
        return False
    if ev.support_obs < fraction * ((ev.support_obs + ev.corner_obs) if told_only else ev.observations):
        return False
    _th, lo, hi = min_area_rect(own)
    return float(np.max(hi - lo)) <= pc.leg_size_max * 1.5


def seen_apart(a: Track, b: Track, min_frames: int) -> bool:
    """True if two objects were seen side by side in at least ``min_frames`` frames and in every frame that
    boxed both through different boxes of known columns: boxes that do not overlap in the image hold
    different bearings, so two objects however their points mix (one box's island is never the other's
    object in every frame). ``min_frames`` 0: never."""
    if min_frames <= 0:
        return False
    apart = 0
    for k in a.boxes.keys() & b.boxes.keys():
        if a.boxes[k] == b.boxes[k]:
            continue
        ca, cb = a.box_cols.get(k), b.box_cols.get(k)
        if ca is None or cb is None:
            continue
        if min(ca[1], cb[1]) > max(ca[0], cb[0]):
            return False  # overlapping boxes in one frame: a double box of one object is possible
        apart += 1
    return apart >= min_frames


# -- evidence in, objects out ---------------------------------------------------------------------------


def _new_frame(t: Track, stamp: float, robot_moved: bool, cfg: ConsciousnessConfig) -> bool:
    return robot_moved or (stamp - t.last_frame_stamp >= float(cfg.stationary_frame_s) > 0.0)


def _frames_window(cfg: ConsciousnessConfig, could_see: int) -> int:
    """``F`` of the soft decision for an object that could have been seen in ``could_see`` frames: the paper's
    ``F``, or with ``min_frames_for_presence`` (improved mode) ``could_see`` clipped to ``[min, F]``."""
    F = max(int(cfg.frames_for_presence), 1)
    m = int(cfg.min_frames_for_presence)
    if m <= 0 or m >= F:
        return F
    return min(F, max(m, int(could_see)))


def presence_frames(t: Track, cfg: ConsciousnessConfig) -> int:
    """``F`` of the soft decision for ``t``'s next frame. The paper's ``F`` assumes an object stays in view for
    at least ``F`` frames; one the robot turns past may be in view for two or three. With
    ``min_frames_for_presence`` (improved mode), ``F`` is the frames it could have been seen in so far (those
    that boxed it, this one included, and its clear misses), clipped to ``[min_frames_for_presence, F]``: an
    object boxed in every frame it was in clear view reaches its confidence, one missed in clear view does not
    (and the presence evidence, :func:`evidence_presence`, still asks for several boxes)."""
    return _frames_window(cfg, t.frames + 1 + t.misses)


def _soft_decision(t: Track, confidence: float, cfg: ConsciousnessConfig) -> tuple[float, int]:
    """The soft decision for ``t``'s new frame with a box of ``confidence``: ``(presence, frames)``. The paper's
    ``Y_c·f/F``, or, judged on the fewer frames it could have been seen in (:func:`presence_frames`), ``Y_c·f/F'``
    with ``Y_c`` the mean of its frames' confidences (thinner evidence: no single good box carries it),
    whichever is higher."""
    yc = t.frame_confidence(confidence, cfg)
    F = max(int(cfg.frames_for_presence), 1)
    p, f = update_presence(t.presence, t.frames, yc, F)
    Fe = presence_frames(t, cfg)
    if Fe < F and t.conf_n > 0:
        p = max(p, update_presence(t.presence, t.frames, min(yc, t.conf_sum / t.conf_n), Fe)[0])
    return p, f


def credit_track(
    t: Track, sight: Sighting, box: int, stamp: float, robot_moved: bool, cfg: ConsciousnessConfig, known_free: FreeFn | None
) -> None:
    """A box that saw ``t`` without giving points: a presence frame and a bisector ray."""
    if _new_frame(t, stamp, robot_moved, cfg) and t.touched_stamp != stamp:
        t.presence, t.frames = _soft_decision(t, sight.confidence, cfg)
        t.last_frame_stamp = stamp
    t.evidence.add_ray(sight.apex, sight.direction, sight.weight, sight.kf, decay=float(cfg.rolling_average_weight))
    t.touched_stamp = stamp
    t.saw(stamp, box, sight.box_cols)
    t.detections += 1
    t.last_seen = max(t.last_seen, stamp)
    t.refresh(known_free)


def add_evidence(ev: ObjectEvidence, cand: Candidate, kf: int, cfg: ConsciousnessConfig) -> None:
    """A candidate's points, ground-plane centre and bisector ray into ``ev``."""
    w = float(cfg.rolling_average_weight)
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
            cand.ray_origin, cand.ray_dir, cand.ray_weight, kf, decay=w, apparent_width=cand.apparent_width, open_side=cand.open_side,
            base_range=cand.base_range,
        )


def create_track(
    track_id: int, cand: Candidate, stamp: float, kf: int, cfg: ConsciousnessConfig, known_free: FreeFn | None
) -> Track:
    """A new object from a candidate (presence ``c/F``)."""
    ev = ObjectEvidence()
    add_evidence(ev, cand, kf, cfg)
    t = Track(
        id=track_id,
        label=cand.label,
        presence=initial_presence(cand.confidence, _frames_window(cfg, 1)),
        frames=1,
        confidence=cand.confidence,
        source=cand.source,
        evidence=ev,
        created=stamp,
        last_seen=stamp,
        last_frame_stamp=stamp,
        touched_stamp=stamp,
    )
    t.saw(stamp, cand.area_index, cand.box_cols)
    t.frame_confidence(cand.confidence, cfg)
    t.complete_views = int(cand.ray_weight > 0.0)
    t.refresh(known_free)
    if t.footprint is None:
        t.footprint = cand.footprint
    return t


def update_track(
    t: Track, cand: Candidate, stamp: float, kf: int, robot_moved: bool, cfg: ConsciousnessConfig, known_free: FreeFn | None
) -> bool:
    """Add a candidate's evidence to a track; False if its points were left out (shape inconsistent)."""
    pc = t.prior
    consistent = True
    if len(cand.points) and t.evidence.has_points:
        trusted = t.evidence.trusted()  # the voxels seen outside its box elsewhere are not its shape
        own = t.evidence.points if trusted is None else t.evidence.points[trusted]
        _th, lo, hi = min_area_rect(np.vstack([own, cand.points]))
        d = hi - lo
        ok = pc.fits_typical(float(d[0]), float(d[1]), tolerance=0.25)
        if ok and cfg.point_ownership and pc.legged and cand.legs and t.evidence.leg_obs * 2 > t.evidence.observations:
            # legs joining legs: together they must still be the legs of one instance (its leg shapes)
            ok = pc.legs_fit(float(d[0]), float(d[1]))
        if not ok:
            # the union would not fit one object of this class: keep the track's shape, use the ray only
            cand = dataclasses.replace(cand, points=np.zeros((0, 2)), ground_center=None)
            consistent = False
        elif (cfg.point_ownership and cand.legs and (cand.support is False or (cfg.support_whole_boxes and cand.support is None))
              and pedestal(t.evidence, own, pc, float(cfg.pedestal_fraction), bool(cfg.support_whole_boxes))):
            # a pedestal stays one: of a group of legs, only those at its support are its own (the legs of
            # stools round a round table); a group with none there says it is no pedestal after all
            at = nearest_distances(cand.points, own) <= pc.leg_size_max
            if at.any():
                cand = dataclasses.replace(cand, points=cand.points[at], support=True)
            else:
                t.evidence.corner_obs += 1
                cand = dataclasses.replace(cand, points=np.zeros((0, 2)), ground_center=None)
                consistent = False
    add_evidence(t.evidence, cand, kf, cfg)
    if cand.source == "lidar_legs" or (cand.source == "lidar_island" and t.source == "ground_plane"):
        t.source = cand.source
    if _new_frame(t, stamp, robot_moved, cfg) and t.touched_stamp != stamp:
        t.presence, t.frames = _soft_decision(t, cand.confidence, cfg)
        t.last_frame_stamp = stamp
    t.touched_stamp = stamp
    t.saw(stamp, cand.area_index, cand.box_cols)
    t.confidence = cand.confidence
    t.detections += 1
    t.complete_views += int(cand.ray_weight > 0.0)
    t.last_seen = stamp
    t.refresh(known_free)
    return consistent


def merge_tracks(keep: Track, drop: Track, cfg: ConsciousnessConfig, known_free: FreeFn | None) -> None:
    """``keep`` absorbs ``drop`` (same object): evidence united, frames added (they were seen in
    different frames), presence re-evaluated with the soft decision."""
    F = max(int(cfg.frames_for_presence), 1)
    keep.evidence.absorb(drop.evidence)
    frames = min(F, keep.frames + drop.frames)
    conf = min(keep.confidence, drop.confidence)
    keep.presence = max(keep.presence, drop.presence, min(conf, 1.0) * frames / F)
    keep.frames = frames
    keep.detections += drop.detections
    keep.apart |= drop.apart - {keep.id}
    keep.complete_views += drop.complete_views
    # a frame in which one of the two was boxed is no miss of the object they both were
    seen_k = {m for m in keep.miss_stamps if m in drop.boxes}
    seen_d = {m for m in drop.miss_stamps if m in keep.boxes}
    keep.misses = max(keep.misses + drop.misses - len(seen_k) - len(seen_d), 0)
    keep.miss_stamps = (keep.miss_stamps | drop.miss_stamps) - seen_k - seen_d
    for k, v in drop.boxes.items():
        keep.boxes.setdefault(k, v)
    for k, c in drop.box_cols.items():
        keep.box_cols.setdefault(k, c)
    keep.last_seen = max(keep.last_seen, drop.last_seen)
    keep.last_frame_stamp = max(keep.last_frame_stamp, drop.last_frame_stamp)
    keep.created = min(keep.created, drop.created)
    keep.refresh(known_free)


def export_track(t: Track, kf_poses: dict[int, Pose2], cfg: ConsciousnessConfig | None = None) -> TrackedObject:
    """The published object (``map`` frame), anchored to its latest keyframe. With ``cfg`` and its
    ``presence_evidence``, its presence is the soft decision's capped by :func:`evidence_presence`."""
    fp = t.footprint
    assert fp is not None
    pose = Pose2(float(fp.center[0]), float(fp.center[1]), float(angle_wrap(fp.yaw)))
    kf = t.evidence.latest_keyframe()
    anchor = kf if kf != NO_KEYFRAME and kf in kf_poses else None
    T_kf_obj = kf_poses[anchor].inverse() @ pose if anchor is not None else None
    presence = float(t.presence)
    if cfg is not None and cfg.presence_evidence:
        presence = min(presence, evidence_presence(t.detections, t.misses, float(cfg.detection_rate),
                                                   float(cfg.false_detection_rate)))
    return TrackedObject(
        id=t.id,
        label=t.label,
        pose=pose,
        size_x=float(fp.size_x),
        size_y=float(fp.size_y),
        size_z=float(t.prior.height[1]),
        presence=presence,
        detection_confidence=float(t.confidence),
        frames_seen=int(t.frames),
        source=t.source,
        frame_id="map",
        anchor_keyframe=anchor,
        T_keyframe_object=T_kf_obj,
        last_seen=float(t.last_seen),
        footprint=fp.corners,
    )
