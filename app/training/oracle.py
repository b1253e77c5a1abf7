"""The ``oracle`` detector: boxes from the simulator's segmentation, with detector-like noise.

It measures the fusion (Consciousness) apart from the network: the same :class:`Detections` as the YOLO
detector, but every box comes from ground truth. A box is reported for each classified object with at
least ``cfg.oracle_min_pixels`` visible pixels and, when the world is known, at least
``cfg.oracle_min_visible_fraction`` of its unoccluded, untruncated silhouette visible (the same measure
that filters the training labels, :mod:`app.training.labels`). Realism:

- the box is the tight box of the visible pixels with each edge moved by ``N(0, oracle_box_jitter_px)``;
- the confidence is ``N(oracle_confidence_mean, oracle_confidence_std)`` lowered by ``0.3·(1 − visible
  fraction)`` (partly hidden objects get lower scores, as from a network), clipped to [0.01, 0.99],
  and boxes below ``cfg.confidence`` are dropped, as the YOLO detector does.

Example:
    >>> oracle = OracleDetector(cfg.detector, np.random.default_rng(0), world=sim.world)
    >>> dets = oracle.detect(sim.render_camera(segmentation=True), sim.ground_truth_objects())
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from app.ocslam.config import DetectorConfig
from app.ocslam.detector import DetectorError
from app.ocslam.messages import CLASS_INDEX, Detection, Detections, GroundTruthObject
from app.training.labels import LabelFilter, make_labels, visible_boxes
from app.training.silhouettes import SilhouetteRenderer

__all__ = ["OracleDetector"]


class OracleDetector:
    """Detections from ground-truth segmentation (see the module docstring).

    ``world`` (the simulator's :class:`app.world.types.World`) enables the visible-fraction test; it may also
    be assigned later (``oracle.world = sim.world``). Without it only the pixel-count test applies.
    """

    def __init__(self, cfg: DetectorConfig, rng: np.random.Generator, world: Any = None) -> None:
        self.cfg = cfg
        self.rng = rng
        self._world = None
        self._silhouettes: SilhouetteRenderer | None = None
        self.world = world

    @property
    def world(self) -> Any:
        return self._world

    @world.setter
    def world(self, world: Any) -> None:
        if self._silhouettes is not None:
            self._silhouettes.close()
            self._silhouettes = None
        self._world = world

    def _full_pixels(self, frame, ids: Sequence[int]) -> dict[int, int]:
        if self._world is None or frame.T_world_camera is None or not ids:
            return {}
        if self._silhouettes is None:
            self._silhouettes = SilhouetteRenderer(self._world)
        info = frame.info
        return self._silhouettes.counts(frame.T_world_camera, info.K, info.width, info.height, ids)

    def detect(self, frame, objects: Sequence[GroundTruthObject]) -> Detections:
        """Boxes for the objects visible in ``frame`` (a ``CameraFrame`` rendered with segmentation)."""
        seg = getattr(frame, "segmentation", None)
        if seg is None:
            raise DetectorError("the oracle detector needs camera frames rendered with segmentation=True")
        cfg = self.cfg
        h, w = seg.shape
        class_of = {int(o.id): CLASS_INDEX[o.label] for o in objects if o.label in CLASS_INDEX}
        vis = visible_boxes(seg)
        cands = [i for i, v in vis.items() if i in class_of and v[4] >= cfg.oracle_min_pixels]
        full = self._full_pixels(frame, cands)
        filt = LabelFilter(
            min_pixels=float(cfg.oracle_min_pixels),
            min_visible_fraction=float(cfg.oracle_min_visible_fraction) if full else 0.0,
            min_box_px=1.0,
            reference_width=w,
            min_in_frame_fraction=0.0,
        )
        ignore = {CLASS_INDEX[n] for n in cfg.ignore_classes if n in CLASS_INDEX}
        boxes = []
        for lb in make_labels(seg, {i: class_of[i] for i in cands}, full, filt):
            if not lb.keep or lb.class_id in ignore:
                continue
            frac = min(1.0, lb.visible_fraction) if full else 1.0
            conf = cfg.oracle_confidence_mean - 0.3 * (1.0 - frac) + cfg.oracle_confidence_std * self.rng.standard_normal()
            conf = float(np.clip(conf, 0.01, 0.99))
            if conf < cfg.confidence:
                continue
            j = cfg.oracle_box_jitter_px * self.rng.standard_normal(4) if cfg.oracle_box_jitter_px > 0 else np.zeros(4)
            x1 = float(np.clip(lb.x1 + j[0], 0, w - 1))
            y1 = float(np.clip(lb.y1 + j[1], 0, h - 1))
            x2 = float(np.clip(lb.x2 + j[2], x1 + 1, w))
            y2 = float(np.clip(lb.y2 + j[3], y1 + 1, h))
            boxes.append(Detection(x1, y1, x2, y2, lb.class_id, conf))
        boxes.sort(key=lambda d: -d.confidence)
        return Detections(stamp=float(frame.stamp), image_width=w, image_height=h, boxes=tuple(boxes))

    def close(self) -> None:
        if self._silhouettes is not None:
            self._silhouettes.close()
            self._silhouettes = None
