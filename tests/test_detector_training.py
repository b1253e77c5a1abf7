"""Smoke test of the training wrapper: 1 epoch on a tiny synthetic dataset, exported ONNX loads in the runtime.

Runs only where the [train] extra is installed (not in `make test`'s default venv).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from app.ocslam.messages import CLASS_NAMES

pytestmark = [pytest.mark.train, pytest.mark.slow]


def _tiny_dataset(root: Path, n_train: int = 12, n_val: int = 4, size: int = 96) -> Path:
    import cv2

    rng = np.random.default_rng(0)
    for split, n in (("train", n_train), ("val", n_val)):
        (root / "images" / split).mkdir(parents=True)
        (root / "labels" / split).mkdir(parents=True)
        for i in range(n):
            img = rng.integers(0, 60, (size, size, 3), dtype=np.uint8)
            lines = []
            for _ in range(2):
                c = int(rng.integers(0, len(CLASS_NAMES)))
                w, h = rng.integers(16, 40, 2)
                x, y = rng.integers(0, size - w), rng.integers(0, size - h)
                colour = tuple(int(v) for v in (40 + 20 * c, 255 - 20 * c, 120))
                cv2.rectangle(img, (int(x), int(y)), (int(x + w), int(y + h)), colour, -1)
                lines.append(f"{c} {(x + w / 2) / size:.6f} {(y + h / 2) / size:.6f} {w / size:.6f} {h / size:.6f}")
            cv2.imwrite(str(root / "images" / split / f"{i}.png"), img)
            (root / "labels" / split / f"{i}.txt").write_text("\n".join(lines) + "\n")
    (root / "data.yaml").write_text(
        yaml.safe_dump(
            {
                "path": str(root),
                "train": "images/train",
                "val": "images/val",
                "names": {i: n for i, n in enumerate(CLASS_NAMES)},
                "ocslam": {"command": "synthetic test", "seed": 0},
            }
        )
    )
    return root


def test_train_wrapper_smoke(tmp_path: Path) -> None:
    pytest.importorskip("ultralytics")
    from app.ocslam.config import DetectorConfig
    from app.ocslam.detector import Detector
    from app.ocslam.messages import Image
    from app.training.train import TrainOptions, train_detector

    data = _tiny_dataset(tmp_path / "data")
    opts = TrainOptions(
        data=data,
        imgsz=64,
        epochs=1,
        hours=None,
        batch=4,
        workers=0,
        cache=False,
        out_model=tmp_path / "model" / "det.onnx",
        runs_dir=tmp_path / "runs",
        config_dir=tmp_path / "yolo",
    )
    res = train_detector(opts, log=lambda *_: None)
    assert res.model_path.exists() and res.card_path.exists()
    card = yaml.safe_load(res.card_path.read_text())
    assert card["classes"] == list(CLASS_NAMES)
    assert card["dataset"]["command"] == "synthetic test"
    assert card["training"]["epochs_run"] == 1
    det = Detector(DetectorConfig(input_size=64), res.model_path)
    assert det.class_names == CLASS_NAMES
    out = det.detect(Image(0.0, np.zeros((96, 96, 3), np.uint8)))
    assert out.image_width == 96
