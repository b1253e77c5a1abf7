"""Evaluation samples: images with their ground-truth boxes, as the detector benchmark scores them.

A :class:`Sample` is one image (a file, or an in-memory RGB array) of ``width × height`` pixels with its
:class:`GtBox` list in pixel ``xyxy``; a box with ``ignore`` set is a COCO ``iscrowd`` region (an object
that is visible but fails the label filter). :func:`load_samples` reads them from the COCO annotations
an ``ocslam dataset`` writes (``annotations_{train,val}.json``).

The types live here, on the training side, so that the benchmark (``app.bench.detector``) imports the
dataset package and never the reverse.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["GtBox", "Sample", "load_samples"]


@dataclass(frozen=True)
class GtBox:
    class_id: int
    x1: float
    y1: float
    x2: float
    y2: float
    ignore: bool = False


@dataclass(frozen=True)
class Sample:
    """One evaluation image: a file (or an in-memory RGB array) and its ground-truth boxes."""

    path: Path | None
    width: int
    height: int
    boxes: tuple[GtBox, ...]
    rgb: np.ndarray | None = None

    def load(self) -> np.ndarray:
        if self.rgb is not None:
            return self.rgb
        import cv2

        bgr = cv2.imread(str(self.path), cv2.IMREAD_COLOR)
        if bgr is None:
            raise FileNotFoundError(f"cannot read image {self.path}")
        return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def load_samples(data_dir: str | Path, split: str = "val") -> list[Sample]:
    """Evaluation samples of a dataset split (``train``, ``val`` or ``all``), with not-kept visible
    objects as ignore boxes."""
    data_dir = Path(data_dir)
    splits = ("train", "val") if split == "all" else (split,)
    out = []
    for s in splits:
        f = data_dir / f"annotations_{s}.json"
        if not f.exists():
            raise FileNotFoundError(f"{f} not found: make the dataset with `ocslam dataset --out {data_dir}`")
        d = json.loads(f.read_text())
        by_img: dict[int, list] = {}
        for a in d["annotations"]:
            x, y, w, h = a["bbox"]
            by_img.setdefault(a["image_id"], []).append(GtBox(a["category_id"] - 1, x, y, x + w, y + h, bool(a["iscrowd"])))
        for im in d["images"]:
            out.append(Sample(data_dir / im["file_name"], im["width"], im["height"], tuple(by_img.get(im["id"], ()))))
    return out
