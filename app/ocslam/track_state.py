"""The tracked objects' saved state (for ``Consciousness.state_dict`` / ``load_state_dict``).

Each object is a JSON-compatible dict: its soft decision, its evidence (points, rays, keyframes) and
its footprint as estimated live (a load reproduces the map exactly, although the occupancy grid that
shaped it is not saved).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from app.ocslam.evidence import ObjectEvidence
from app.ocslam.footprint import Footprint
from app.ocslam.messages import CLASS_NAMES
from app.ocslam.tracks import Track


def tracks_state(tracks: list[Track]) -> list[dict[str, Any]]:
    """JSON-compatible state of the tracked objects."""
    return [
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
            "conf": [t.conf_sum, t.conf_n, t.conf_best],
            "footprint": None
            if t.footprint is None
            else [float(t.footprint.center[0]), float(t.footprint.center[1]), float(t.footprint.yaw),
                  float(t.footprint.size_x), float(t.footprint.size_y)],
            "evidence": t.evidence.state_dict(),
            "apart": sorted(t.apart),
        }
        for t in tracks
    ]


def tracks_from_state(items: list[dict[str, Any]]) -> list[Track]:
    """The tracked objects of :func:`tracks_state`; raises ``ValueError`` (unknown class, bad
    evidence), ``KeyError`` or ``TypeError`` on a malformed state."""
    tracks = []
    for td in items:
        label = str(td["label"])
        if label not in CLASS_NAMES:
            raise ValueError(f"unknown class {label!r}")
        t = Track(
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
            apart={int(v) for v in td.get("apart", [])},
        )
        conf = td.get("conf")
        if conf is not None and len(conf) == 3 and all(math.isfinite(float(v)) for v in conf):
            t.conf_sum, t.conf_n, t.conf_best = float(conf[0]), int(conf[1]), float(conf[2])
        fp = td.get("footprint")
        if fp is not None and len(fp) == 5 and all(math.isfinite(float(v)) for v in fp):
            # as estimated live (with the occupancy grid then at hand)
            t.footprint = Footprint(np.array([float(fp[0]), float(fp[1])]), float(fp[2]), float(fp[3]), float(fp[4]))
        else:
            t.refresh()
        tracks.append(t)
    return tracks
