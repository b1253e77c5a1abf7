"""The detector benchmark's evaluation (pycocotools) on hand-made detections with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from app.bench.detector import coco_evaluate
from app.training.samples import GtBox, Sample


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


def _test_render_dataset(root):
    """The committed test renders (tests/data/detector) as an `ocslam dataset`-style val split."""
    import json
    import shutil
    from pathlib import Path

    import yaml

    from app.ocslam.messages import CLASS_INDEX

    src = Path(__file__).resolve().parent / "data" / "detector"
    (root / "images" / "val").mkdir(parents=True)
    images, anns = [], []
    for i, e in enumerate(yaml.safe_load((src / "expected.yaml").read_text())):
        shutil.copyfile(src / e["image"], root / "images" / "val" / e["image"])
        images.append({"id": i + 1, "file_name": f"images/val/{e['image']}", "width": 320, "height": 240})
        for o in e["objects"]:
            x1, y1, x2, y2 = o["box"]
            anns.append({"id": len(anns) + 1, "image_id": i + 1, "category_id": CLASS_INDEX[o["class"]] + 1,
                         "bbox": [x1, y1, x2 - x1, y2 - y1], "area": (x2 - x1) * (y2 - y1), "iscrowd": 0})
    (root / "annotations_val.json").write_text(json.dumps({"images": images, "annotations": anns}))
    return root


def test_compare_runs_both_models_on_the_same_images(tmp_path, capsys) -> None:
    import argparse
    import json
    from pathlib import Path

    import yaml

    from app.bench import detector as bench

    models = Path(__file__).resolve().parents[1] / "assets" / "models"
    float_ref = yaml.safe_load((models / "detector.yaml").read_text())["lineage"]["previous"]["file"]
    assert float_ref != "detector.onnx" and (models / float_ref).is_file()
    assert bench.previous_model(models / "detector.onnx") == models / float_ref
    data = _test_render_dataset(tmp_path / "data")
    p = argparse.ArgumentParser()
    bench.add_arguments(p)
    p.add_argument("--json", action="store_true")
    args = p.parse_args(["--data", str(data), "--compare", "--latency-images", "4", "--json"])
    assert bench.run(args) == 0
    out = json.loads(capsys.readouterr().out)
    assert [Path(m["model"]).name for m in out["models"]] == [float_ref, "detector.onnx"]
    for m in out["models"]:
        assert m["instances"] == 23 and m["map50"] > 0.8  # both find the test renders' objects
        assert set(m["latency_app_ms"]) == {"1", "2"} and m["latency_app_ms"]["2"]["n"] == 4
    assert out["latency_image_size"] == "320x240"  # the app's render size
    assert out["speedup_vs_first"]["2"][0] == 1.0 and len(out["speedup_vs_first"]["2"]) == 2
    # A model that is not there is one clear error line, exit 2.
    args = p.parse_args(["--data", str(data), "--model", str(tmp_path / "nope.onnx"), "--json"])
    assert bench.run(args) == 2
    assert capsys.readouterr().err.startswith("ocslam: error: detector model not found")


def test_app_images_keep_the_aspect() -> None:
    from app.bench.detector import app_images

    out = app_images([np.zeros((480, 640, 3), np.uint8), np.zeros((240, 320, 3), np.uint8)], 320)
    assert [im.shape for im in out] == [(240, 320, 3), (240, 320, 3)]
