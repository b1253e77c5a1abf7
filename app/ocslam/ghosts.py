"""Ghost decay (improved mode): objects in clear view that no box explains lose presence.

A frame is a *clear miss* for an object when its centre projects inside the image, lies within
``decay_max_range_m``, no box of its class covers its bearing, and the LIDAR does not see something in
front of it. An object decays only once its clear misses outnumber its detections.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from app.ocslam.camera import CameraModel
from app.ocslam.candidate import FrameReport
from app.ocslam.config import ConsciousnessConfig
from app.ocslam.presence import centers_in_camera_view, decay_presence, occluded_by_scan
from app.ocslam.projection import BoundingArea
from app.ocslam.se2 import Pose2
from app.ocslam.tracks import Track

FloatArray = NDArray[np.float64]


def decay_tracks(
    tracks: list[Track],
    areas: Sequence[BoundingArea],
    T_map_base: Pose2,
    T_map_scan: Pose2,
    beam_b_scan: FloatArray,
    beam_r_scan: FloatArray,
    stamp: float,
    dt: float,
    rep: FrameReport,
    cfg: ConsciousnessConfig,
    cam: CameraModel,
) -> list[Track]:
    """Ghost decay; returns the tracks that remain (presence > 0).

    The per-track tests that need no scan (explained by a box's wedge, in the camera's view) run for
    every track at once; the occlusion test only for the tracks still missed."""
    T_scan_map = T_map_scan.inverse()
    T_base_map = T_map_base.inverse()
    labels = {a.label for a in areas}
    cand = [i for i, t in enumerate(tracks) if t.footprint is not None and t.touched_stamp != stamp]
    missed = np.zeros(len(tracks), dtype=bool)
    if cand:
        fps = [tracks[i].footprint for i in cand]
        centers = np.array([fp.center for fp in fps if fp is not None], dtype=np.float64).reshape(-1, 2)
        # explained by a box of its class whose wedge holds it
        explained = np.zeros(len(cand), dtype=bool)
        boxed = np.array([tracks[i].label in labels for i in cand])
        if np.any(boxed):
            b, _r = cam.bearing_ranges_scan(T_scan_map.transform_points(centers[boxed]))
            held = np.zeros(len(b), dtype=bool)
            cand_labels = np.array([tracks[i].label for i in cand], dtype=object)[boxed]
            for a in areas:
                held |= (cand_labels == a.label) & a.contains_bearing(b, margin=0.05)
            explained[np.flatnonzero(boxed)] = held
        heights = np.array([tracks[i].prior.height[1] for i in cand], dtype=np.float64)
        in_view = centers_in_camera_view(centers, heights, T_base_map, cam, float(cfg.decay_max_range_m))
        missed[np.asarray(cand)[~explained & in_view]] = True
    keep = []
    for i, t in enumerate(tracks):
        if not missed[i]:
            keep.append(t)
            continue
        fp = t.footprint
        assert fp is not None
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
    return keep
