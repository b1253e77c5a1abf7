"""`train-detector --init-onnx`: the committed float model (assets/models/detector-v3.onnx) converted back
into a trainable ultralytics checkpoint (app/training/onnx_init.py) computes the same outputs as the
ONNX model under onnxruntime, with identity or calibrated BatchNorms, and ultralytics takes every tensor
of it as ``pretrained=``. The conversion tests need the [train] extra (skipped without torch or
ultralytics); the command-line checks do not."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
FLOAT = ROOT / "assets" / "models" / "detector-v3.onnx"
RENDERS = sorted((ROOT / "tests" / "data" / "detector").glob("*.png"))  # the app's 320×240, one per class

#: Raw output [1, 4 + 11, N]: boxes in input pixels (hundreds), class scores in [0, 1].
BOX_TOL_REL = 1e-5  # of the largest box coordinate (measured ≈ 6e-7: 3e-4 px of 556 px)
SCORE_TOL = 1e-5  # measured ≈ 5e-7


def _train_extra():
    from app.training.train import setup_offline

    setup_offline(ROOT / ".yolo")  # before ultralytics is imported: its settings stay in the project, offline
    pytest.importorskip("torch")
    pytest.importorskip("ultralytics")
    pytest.importorskip("onnx")
    import torch

    return torch


@pytest.fixture(scope="module")
def session():
    ort = pytest.importorskip("onnxruntime")
    return ort.InferenceSession(str(FLOAT), providers=["CPUExecutionProvider"])


def _inputs() -> dict[str, np.ndarray]:
    """Random 224×192 (the app's input for its 320×240 renders) and the committed renders, letterboxed to
    224×224 as ultralytics trains them."""
    from app.training.onnx_init import _letterbox_batch

    rng = np.random.default_rng(0)
    return {
        "random 1×3×192×224": rng.random((1, 3, 192, 224), dtype=np.float32),
        "renders 11×3×224×224": _letterbox_batch(RENDERS, 224).numpy(),
    }


def _max_diffs(model, session, x: np.ndarray) -> tuple[float, float, float]:
    """(max |Δ box|, max |Δ score|, max |box|) between the torch model (eval) and onnxruntime on x."""
    import torch

    ref = session.run(None, {"images": x})[0]
    with torch.no_grad():
        y = model.eval()(torch.from_numpy(x))
    y = (y[0] if isinstance(y, (tuple, list)) else y).numpy()
    assert y.shape == ref.shape
    d = np.abs(y - ref)
    return float(d[:, :4].max()), float(d[:, 4:].max()), float(np.abs(ref[:, :4]).max())


@pytest.mark.train
@pytest.mark.slow
@pytest.mark.parametrize("calibrated", [False, True], ids=["identity-bn", "calibrated-bn"])
def test_converted_checkpoint_computes_the_onnx_outputs(tmp_path: Path, session, calibrated: bool) -> None:
    torch = _train_extra()
    from app.training.onnx_init import onnx_to_checkpoint

    res = onnx_to_checkpoint(FLOAT, tmp_path / "v3.pt", calib_images=RENDERS if calibrated else None)
    assert res.checkpoint.is_file() and res.bn_calibrated is calibrated
    assert res.convs_loaded == 63 and res.matched_by_name == 64 and res.matched_by_order == 0  # + the DFL
    for what, x in _inputs().items():
        box, score, scale = _max_diffs(res.model, session, x)
        print(f"{what} ({'calibrated' if calibrated else 'identity'} BN): max |Δ| boxes {box:.2e} px "
              f"(of {scale:.0f}), scores {score:.2e}")
        assert box <= BOX_TOL_REL * scale, what
        assert score <= SCORE_TOL, what
    bns = [m for m in res.model.modules() if isinstance(m, torch.nn.BatchNorm2d)]
    if calibrated:  # real statistics, not the identity
        assert all(float(b.running_var.mean()) != pytest.approx(1.0 - b.eps) for b in bns)
    else:
        assert all(torch.all(b.weight == 1) and torch.all(b.running_mean == 0) for b in bns)


@pytest.mark.train
@pytest.mark.slow
def test_ultralytics_takes_every_tensor_as_pretrained(tmp_path: Path, session) -> None:
    torch = _train_extra()
    from ultralytics.nn.tasks import load_checkpoint

    from app.ocslam.messages import CLASS_NAMES
    from app.training.onnx_init import build_detection_model, onnx_to_checkpoint

    pt = onnx_to_checkpoint(FLOAT, tmp_path / "v3.pt").checkpoint
    weights, ckpt = load_checkpoint(str(pt))  # what the trainer does with pretrained=<pt>
    assert ckpt["ema"] is None and ckpt["optimizer"] is None and ckpt["epoch"] == -1
    fresh = build_detection_model()  # what the trainer builds from yolov8n.yaml
    fresh.load(weights, verbose=False)
    ours, theirs = weights.state_dict(), fresh.state_dict()
    assert ours.keys() == theirs.keys()
    assert all(torch.equal(ours[k], theirs[k]) for k in ours)
    assert fresh.names == dict(enumerate(CLASS_NAMES))
    box, score, scale = _max_diffs(fresh, session, _inputs()["random 1×3×192×224"])
    assert box <= BOX_TOL_REL * scale and score <= SCORE_TOL


@pytest.mark.train
@pytest.mark.slow
def test_another_architecture_is_refused_in_one_line(tmp_path: Path) -> None:
    _train_extra()
    from app.training.onnx_init import OnnxInitError, onnx_to_checkpoint

    with pytest.raises(OnnxInitError) as e:
        onnx_to_checkpoint(FLOAT, tmp_path / "s.pt", model_yaml="yolov8s.yaml")  # twice the widths
    msg = str(e.value)
    assert "\n" not in msg and "/model.0/conv/Conv" in msg and "model.0.conv" in msg and "weight 16×3×3×3 vs 32×3×3×3" in msg
    assert not (tmp_path / "s.pt").exists()


@pytest.mark.train
def test_missing_onnx_is_a_clear_error(tmp_path: Path) -> None:
    _train_extra()
    from app.training.onnx_init import onnx_to_checkpoint

    with pytest.raises(FileNotFoundError, match="no ONNX model at"):
        onnx_to_checkpoint(tmp_path / "nope.onnx", tmp_path / "x.pt")


# -- the command line (no torch needed: refused before anything is imported or rendered) ------------------


def _args(tmp: Path, *argv: str) -> argparse.Namespace:
    from app.commands.train_detector import add_arguments

    p = argparse.ArgumentParser()
    add_arguments(p)
    return p.parse_args(["--data", str(tmp / "no-data"), "--runs", str(tmp / "runs"), *argv])


@pytest.mark.parametrize("other", [["--init-weights", "x.pt"], ["--resume"]], ids=["init-weights", "resume"])
def test_init_onnx_excludes_other_weight_sources(tmp_path: Path, capsys, other: list[str]) -> None:
    from app.commands.train_detector import run

    assert run(_args(tmp_path, "--init-onnx", str(FLOAT), *other)) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"ocslam: error: --init-onnx and {other[0]} exclude each other (both say where the weights come from)"
    assert not (tmp_path / "no-data").exists()  # nothing rendered


def test_init_onnx_missing_file(tmp_path: Path, capsys) -> None:
    from app.commands.train_detector import run

    assert run(_args(tmp_path, "--init-onnx", str(tmp_path / "missing.onnx"))) == 2
    assert capsys.readouterr().err.strip() == f"ocslam: error: --init-onnx: no ONNX model at {tmp_path / 'missing.onnx'}"


def test_calibration_images_follow_the_data_yaml(tmp_path: Path) -> None:
    from app.commands.train_detector import _calibration_images

    for sub in ("a/images/train", "b/images/train"):
        (tmp_path / sub).mkdir(parents=True)
        for i in range(5):
            (tmp_path / sub / f"{i}.png").write_bytes(b"")
    (tmp_path / "combined.yaml").write_text(f"path: {tmp_path}\ntrain: [a/images/train, b/images/train]\nval: a/images/val\n")
    got = _calibration_images(tmp_path / "combined.yaml", 4)
    assert len(got) == 4 and {p.parent.parent.parent.name for p in got} == {"a", "b"}
    assert len(_calibration_images(tmp_path / "combined.yaml", 100)) == 10
    assert _calibration_images(tmp_path / "combined.yaml", 0) == []
    # an `ocslam dataset` folder: data.yaml without `path`, train relative to its folder
    (tmp_path / "a" / "data.yaml").write_text("train: images/train\nval: images/val\n")
    for data in (tmp_path / "a", tmp_path / "a" / "data.yaml"):
        assert [p.name for p in _calibration_images(data, 2)] == ["0.png", "2.png"]
