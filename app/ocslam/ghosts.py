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
from app.ocslam.presence import decay_presence, in_camera_view, occluded_by_scan
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
    """Ghost decay; returns the tracks that remain (presence > 0)."""
    T_scan_map = T_map_scan.inverse()
    T_base_map = T_map_base.inverse()
    labels = {a.label for a in areas}
    keep = []
    for t in tracks:
        fp = t.footprint
        if fp is None or t.touched_stamp == stamp:
            keep.append(t)
            continue
        # explained by a box of its class whose wedge holds it
        if t.label in labels:
            c_scan = T_scan_map.transform_points(fp.center[None, :])
            b, _r = cam.bearing_ranges_scan(c_scan)
            if any(a.label == t.label and bool(a.contains_bearing(b, margin=0.05)[0]) for a in areas):
                keep.append(t)
                continue
        if not in_camera_view(fp, t.prior.height[1], T_map_base, cam, float(cfg.decay_max_range_m), T_base_frame=T_base_map):
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
    return keep
