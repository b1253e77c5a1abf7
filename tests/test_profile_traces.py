"""The trace-replay script's choice of recordings and of the score calibration they are read with."""

from __future__ import annotations

import hashlib
import json
import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))

import profile_traces as P  # noqa: E402

from app.ocslam.detector import model_score_calibration, score_calibration_for  # noqa: E402

MODEL = ROOT / "assets" / "models" / "detector-n8r-int8.onnx"  # a committed model whose card has a calibration


def _recording(cache: Path, name: str, meta: dict, mtime: float) -> Path:
    d = cache / name
    d.mkdir(parents=True)
    (d / "recording.json").write_text(json.dumps(meta))
    os.utime(d / "recording.json", (mtime, mtime))
    trace = d / "trace-0.pkl"
    trace.write_bytes(b"")
    return trace


def test_a_yolo_recording_is_replayed_with_its_own_models_calibration(tmp_path: Path):
    sha = hashlib.sha256(MODEL.read_bytes()).hexdigest()
    own = _recording(tmp_path, "w-1", {"detector": "yolo", "detector_model_sha256": sha}, 1.0)
    cfg = P.replay_config(own, ["consciousness.presence_threshold=0.7"])
    assert Path(cfg.detector.model_path) == MODEL and cfg.consciousness.presence_threshold == 0.7
    expected = model_score_calibration(MODEL)
    assert expected is not None and score_calibration_for(cfg.detector) == expected
    # the app's default model has another calibration: replaying with it would read the scores wrongly
    from app.config import Config

    assert score_calibration_for(Config().detector) != expected


def test_a_recording_of_a_model_not_here_is_replayed_uncalibrated(tmp_path: Path, capsys: pytest.CaptureFixture):
    lost = _recording(tmp_path, "w-2", {"detector": "yolo", "detector_model_sha256": "0" * 64}, 1.0)
    cfg = P.replay_config(lost, [])
    assert cfg.detector.calibration == "off" and "not here" in capsys.readouterr().err
    oracle = _recording(tmp_path, "w-3", {"detector": "oracle"}, 1.0)
    assert P.replay_config(oracle, []).detector.kind == "oracle"


def test_each_world_and_model_is_replayed_once_from_its_earliest_recording(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    cache = tmp_path / "runs" / "sweep-cache"
    meta = {"detector": "yolo", "detector_model_sha256": "ab" * 32}
    late = _recording(cache, "hall-bbb", meta, 2000.0)
    early = _recording(cache, "hall-ccc", meta, 1000.0)
    other = _recording(cache, "hall-ddd", {"detector": "yolo", "detector_model_sha256": "cd" * 32}, 3000.0)
    oracle = _recording(cache, "hall-eee", {"detector": "oracle"}, 500.0)
    monkeypatch.chdir(tmp_path)
    found = P.suite_traces("all", "yolo", "any")
    assert {f.resolve() for f in found} == {early.resolve(), other.resolve()} and late.resolve() not in found
    assert [f.resolve() for f in P.suite_traces("all", "oracle", "any")] == [oracle.resolve()]
