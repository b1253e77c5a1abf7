"""The detector benchmark's evaluation (pycocotools) on hand-made detections with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from app.bench.detector import GtBox, Sample, coco_evaluate


def _samples() -> list[Sample]:
    return [
        Sample(None, 320, 240, (GtBox(0, 10, 10, 50, 50), GtBox(3, 100, 100, 200, 180), GtBox(5, 250, 20, 300, 200, ignore=True))),
        Sample(None, 320, 240, (GtBox(0, 60, 60, 90, 90),)),
    ]


def dets(rows):
    rows = np.asarray(rows, dtype=np.float64).reshape(-1, 6)
    return rows[:, :4], rows[:, 4], rows[:, 5].astype(np.int64)


def test_perfect_detections_score_one() -> None:
    r = coco_evaluate(_samples(), [dets([[10, 10, 50, 50, 0.9, 0], [100, 100, 200, 180, 0.8, 3]]), dets([[60, 60, 90, 90, 0.7, 0]])], 0.4)
    assert r["map50"] == pytest.approx(1.0) and r["map50_95"] == pytest.approx(1.0)
    assert r["precision"] == 1.0 and r["recall"] == 1.0 and r["instances"] == 3
    assert r["per_class"]["ball"] == {"precision": 1.0, "recall": 1.0, "ap50": pytest.approx(1.0), "instances": 2}
    assert np.isnan(r["per_class"]["dog"]["recall"])  # no dogs in the data


def test_threshold_false_positives_and_ignore_regions() -> None:
    d0 = dets([
        [10, 10, 50, 50, 0.9, 0],
        [100, 100, 200, 180, 0.3, 3],  # the table, below the 0.4 threshold: a miss at the threshold
        [255, 30, 295, 190, 0.8, 5],  # on the ignored door: neither true nor false positive
        [150, 10, 190, 40, 0.6, 2],  # a gnome that is not there: false positive
    ])
    d1 = dets([[61, 61, 91, 91, 0.7, 0], [0, 150, 40, 200, 0.95, 0]])  # the ball, and a confident false ball
    r = coco_evaluate(_samples(), [d0, d1], 0.4)
    assert r["precision"] == pytest.approx(2 / 4)  # TP: 2 balls; FP: gnome, false ball
    assert r["recall"] == pytest.approx(2 / 3)
    assert r["per_class"]["table"]["recall"] == 0.0 and r["per_class"]["table"]["ap50"] == pytest.approx(1.0)
    assert r["per_class"]["ball"]["precision"] == pytest.approx(2 / 3)
    assert r["per_class"]["door"]["instances"] == 0
    assert r["per_class"]["ball"]["ap50"] < 0.8 and r["map50"] == pytest.approx((r["per_class"]["ball"]["ap50"] + 1.0) / 2)


def test_no_detections() -> None:
    r = coco_evaluate(_samples(), [dets([]), dets([])], 0.4)
    assert r["map50"] == 0.0 and r["recall"] == 0.0
