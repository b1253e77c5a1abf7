"""The committed model (assets/models/detector.onnx) and its card: it loads, and finds the expected
objects on a few small committed renders (tests/data/detector, made by make_images.py there)."""

from __future__ import annotations

import hashlib
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from app.ocslam.config import DetectorConfig
from app.ocslam.detector import Detector
from app.ocslam.messages import CLASS_NAMES, Image

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "assets" / "models" / "detector.onnx"
CARD = ROOT / "assets" / "models" / "detector.yaml"
DATA = ROOT / "tests" / "data" / "detector"


def iou(a, b) -> float:
    ix = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    iy = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = ix * iy
    return inter / ((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter)


@pytest.fixture(scope="module")
def detector() -> Detector:
    return Detector(DetectorConfig(), MODEL)


def test_model_card_describes_the_committed_model(detector: Detector) -> None:
    card = yaml.safe_load(CARD.read_text())
    assert card["classes"] == list(CLASS_NAMES)
    assert card["model"]["sha256"] == hashlib.sha256(MODEL.read_bytes()).hexdigest()
    assert card["input"]["width"] == detector.trained_width == 224
    assert detector.input_size == (224, 192)
    assert card["dataset"]["command"].startswith("ocslam dataset") and card["dataset"]["seed"] is not None
    for k in ("precision", "recall", "map50", "map50_95"):
        assert 0.0 < card["validation"][k] <= 1.0
    assert MODEL.stat().st_size < 15e6


def test_committed_model_finds_the_expected_classes(detector: Detector) -> None:
    entries = yaml.safe_load((DATA / "expected.yaml").read_text())
    assert {Path(e["image"]).stem for e in entries} == set(CLASS_NAMES)
    found = total = 0
    for e in entries:
        bgr = cv2.imread(str(DATA / e["image"]))
        dets = detector.detect(Image(0.0, np.ascontiguousarray(bgr[:, :, ::-1])))
        for obj in e["objects"]:
            total += 1
            hit = any(d.label == obj["class"] and iou((d.x1, d.y1, d.x2, d.y2), obj["box"]) >= 0.5 for d in dets.boxes)
            found += hit
            if obj["class"] == Path(e["image"]).stem:  # the object each image was rendered for
                assert hit, f"{e['image']}: no {obj['class']} at {obj['box']}; got {[(d.label, round(d.confidence, 2)) for d in dets.boxes]}"
    assert found >= 0.8 * total
