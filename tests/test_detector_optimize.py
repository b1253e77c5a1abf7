"""`ocslam train-detector --optimize`: the static-shape int8 model made from the float one, with its card.

Needs onnx and onnxslim (the [train] extra, or pip install onnx onnxslim); skipped without them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
FLOAT = ROOT / "assets" / "models" / "detector-v3.onnx"
DATA = ROOT / "tests" / "data" / "detector"


def test_static_model_and_fast_dfl_keep_the_outputs(tmp_path: Path) -> None:
    pytest.importorskip("onnx")
    pytest.importorskip("onnxslim")
    import onnxruntime as ort

    from app.training.optimize import static_model

    out = tmp_path / "static.onnx"
    summary = static_model(FLOAT, out, 224, 192)
    assert summary["output"] == [1, 15, 882] and summary["fast_dfl"]
    x = np.random.default_rng(0).random((1, 3, 192, 224), dtype=np.float32)
    a = ort.InferenceSession(str(FLOAT)).run(None, {"images": x})[0]
    b = ort.InferenceSession(str(out)).run(None, {"images": x})[0]
    assert ort.InferenceSession(str(out)).get_inputs()[0].shape == [1, 3, 192, 224]
    np.testing.assert_allclose(b[0, 4:], a[0, 4:], atol=1e-5)  # class scores
    np.testing.assert_allclose(b[0, :4], a[0, :4], atol=2e-3)  # boxes in input pixels (DFL rewritten)


@pytest.mark.slow
def test_optimize_command_writes_an_int8_model_and_its_card(tmp_path: Path) -> None:
    pytest.importorskip("onnx")
    pytest.importorskip("onnxslim")
    import shutil

    import cv2

    from app.cli import main
    from app.ocslam.config import DetectorConfig
    from app.ocslam.detector import Detector
    from app.ocslam.messages import Image

    src = tmp_path / "float.onnx"
    shutil.copyfile(FLOAT, src)
    out = tmp_path / "int8.onnx"
    assert main(["train-detector", "--optimize", str(src), "--calib", str(DATA), "--calib-images", "11",
                 "--out", str(out)]) == 0
    card = yaml.safe_load(out.with_suffix(".yaml").read_text())
    assert card["model"]["file"] == "int8.onnx" and card["input"]["static"] is True
    assert card["lineage"]["previous"]["file"] == "float.onnx"
    assert card["quantization"]["calibration_data"]["images_used"] == 11
    det = Detector(DetectorConfig(), out)  # the hash check passes against the new card
    assert det.sha256 == card["model"]["sha256"] and det.input_size == (224, 192)
    assert Detector(DetectorConfig(), src).sha256 == card["variants"][0]["sha256"]  # the float one is described too
    # without --out the int8 model goes beside the float one, never over the app's model
    app_model = Path("assets/models/detector.onnx")
    before = app_model.read_bytes() if app_model.exists() else None
    assert main(["train-detector", "--optimize", str(src), "--calib", str(DATA), "--calib-images", "11"]) == 0
    assert (tmp_path / "float-int8.onnx").is_file() and (tmp_path / "float-int8.yaml").is_file()
    assert (app_model.read_bytes() if app_model.exists() else None) == before
    hits = 0
    for e in yaml.safe_load((DATA / "expected.yaml").read_text()):
        rgb = np.ascontiguousarray(cv2.imread(str(DATA / e["image"]))[:, :, ::-1])
        hits += any(d.label == Path(e["image"]).stem for d in det.detect(Image(0.0, rgb)).boxes)
    assert hits >= 10  # of 11: calibrated on 11 images only, it still finds (nearly) every class
    assert main(["train-detector", "--optimize", str(tmp_path / "none.onnx"), "--out", str(out)]) == 2
