"""Score calibration (Platt scaling): the fit, its card entry, the detector and the soft decision reading it."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from synthetic_scene import Box, Cylinder, default_camera, detection, detections, raycast

from app.ocslam.calibration import ScoreCalibration, expected_calibration_error, fit_platt, reliability
from app.ocslam.config import ConsciousnessConfig, DetectorConfig
from app.ocslam.consciousness import Consciousness
from app.ocslam.detector import (
    Detector,
    DetectorError,
    detector_score_calibration,
    model_score_calibration,
    score_calibration_for,
)
from app.ocslam.se2 import Pose2
from app.training.samples import GtBox, Sample
from app.training.score_calibration import match_boxes, write_card_calibration

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "assets" / "models" / "detector.onnx"


# -- the map -------------------------------------------------------------------------------------------


def test_identity_returns_the_score():
    cal = ScoreCalibration()
    assert cal.is_identity
    assert cal.probability(0.37) == 0.37
    np.testing.assert_array_equal(cal.probabilities([0.1, 0.9]), [0.1, 0.9])


def test_known_answer():
    cal = ScoreCalibration(2.0, 1.0)
    # logit(0.5) = 0 → σ(1) ; logit(0.75) = ln 3 → σ(2 ln 3 + 1) = 9e / (1 + 9e)
    assert cal.probability(0.5) == pytest.approx(1 / (1 + np.exp(-1.0)))
    assert cal.probability(0.75) == pytest.approx(9 * np.e / (1 + 9 * np.e))


@given(st.floats(0.2, 5.0), st.floats(-3.0, 3.0), st.lists(st.floats(0.0, 1.0), min_size=2, max_size=30))
@settings(max_examples=60, deadline=None)
def test_probabilities_are_monotone_and_bounded(slope, offset, scores):
    cal = ScoreCalibration(slope, offset)
    s = np.sort(np.asarray(scores))
    p = cal.probabilities(s)
    assert np.all((p >= 0.0) & (p <= 1.0))
    assert np.all(np.diff(p) >= -1e-12)


def test_fit_recovers_known_parameters():
    rng = np.random.default_rng(0)
    s = rng.uniform(0.05, 0.95, 20000)
    true = ScoreCalibration(2.5, 0.8)
    y = rng.random(len(s)) < true.probabilities(s)
    fit = fit_platt(s, y)
    assert fit.slope == pytest.approx(2.5, abs=0.15)
    assert fit.offset == pytest.approx(0.8, abs=0.1)
    assert expected_calibration_error(fit.probabilities(s), y) < expected_calibration_error(s, y)


def test_fit_of_calibrated_scores_is_near_identity():
    rng = np.random.default_rng(1)
    s = rng.uniform(0.02, 0.98, 20000)
    fit = fit_platt(s, rng.random(len(s)) < s)
    assert fit.slope == pytest.approx(1.0, abs=0.08)
    assert fit.offset == pytest.approx(0.0, abs=0.08)


def test_fit_stays_finite_on_separable_data_and_refuses_one_sided_data():
    fit = fit_platt([0.41, 0.45, 0.9, 0.95], [False, False, True, True])
    assert np.isfinite(fit.slope) and np.isfinite(fit.offset) and fit.slope > 0
    with pytest.raises(ValueError, match="at least 2 right and 2 wrong"):
        fit_platt([0.5, 0.6, 0.7], [True, True, True])


def test_reliability_bins():
    rows = reliability([0.05, 0.15, 0.16, 0.95], [False, True, False, True], bins=10)
    assert [(r["lo"], r["boxes"], r["share_right"]) for r in rows] == [(0.0, 1, 0.0), (0.1, 2, 0.5), (0.9, 1, 1.0)]


@pytest.mark.parametrize("bad", [None, {"slope": 0.0, "offset": 0.0}, {"slope": -1, "offset": 0}, {"slope": "x", "offset": 0},
                                 {"offset": 1.0}, {"slope": float("nan"), "offset": 0}])
def test_malformed_card_entries_are_refused(bad):
    with pytest.raises(ValueError):
        ScoreCalibration.from_dict(bad)


# -- matching boxes to labels -------------------------------------------------------------------------


def test_match_boxes_best_score_first_and_ignored_objects():
    s = Sample(path=None, width=100, height=100,
               boxes=(GtBox(0, 10, 10, 50, 50, False), GtBox(0, 60, 60, 90, 90, True)))
    boxes = np.array([[11, 11, 50, 50], [10, 10, 49, 51], [60, 60, 90, 90], [10, 10, 50, 50]], dtype=float)
    scores = np.array([0.6, 0.9, 0.7, 0.5])
    classes = np.array([0, 0, 0, 1])
    out = match_boxes(s, boxes, scores, classes)
    # the 0.9 box takes the object, the 0.6 duplicate is wrong, the box on the ignored object counts
    # neither way, and a box of another class on the object is wrong
    assert out.tolist() == [0, 1, -1, 0]


# -- the committed model's card -----------------------------------------------------------------------


def test_the_app_model_has_a_calibration_fitted_on_unseen_worlds():
    card = yaml.safe_load((ROOT / "assets/models/detector.yaml").read_text())
    entry = card["model"]["score_calibration"]
    assert entry["method"] == "platt" and entry["slope"] > 0
    assert entry["ece_after"] < entry["ece_before"]
    # fitted on worlds the network never saw: not a training dataset's seed, nor a held-out test seed
    train_seeds = card["dataset"]["seed"]
    assert entry["fitted_on"]["seed"] not in [*train_seeds, 98, 99]
    assert "--no-randomize" in entry["fitted_on"]["dataset_command"]  # rendered as the app renders
    cal = model_score_calibration(MODEL)
    assert cal == ScoreCalibration.from_dict(entry)


def test_detector_applies_its_card_unless_turned_off():
    cfg = DetectorConfig()
    det = Detector(cfg, MODEL)
    assert det.score_calibration == model_score_calibration(MODEL)
    assert not det.score_calibration.is_identity
    assert detector_score_calibration(det) == det.score_calibration
    assert score_calibration_for(cfg) == det.score_calibration
    cfg_off = DetectorConfig()
    cfg_off.calibration = "off"
    assert Detector(cfg_off, MODEL).score_calibration.is_identity
    assert score_calibration_for(cfg_off).is_identity
    cfg_oracle = DetectorConfig()
    cfg_oracle.kind = "oracle"
    assert score_calibration_for(cfg_oracle).is_identity
    assert detector_score_calibration(None).is_identity


def test_card_calibration_is_ignored_for_other_weights_and_rejected_when_malformed(tmp_path):
    model = tmp_path / "detector.onnx"
    shutil.copy(MODEL, model)
    card = yaml.safe_load((ROOT / "assets/models/detector.yaml").read_text())
    (tmp_path / "detector.yaml").write_text(yaml.safe_dump(card))
    assert model_score_calibration(model) == model_score_calibration(MODEL)
    card["model"]["sha256"] = "0" * 64  # a calibration fitted for other weights
    (tmp_path / "detector.yaml").write_text(yaml.safe_dump(card))
    assert model_score_calibration(model) is None
    card["model"]["sha256"] = model_score_calibration.__globals__["file_sha256"](model)
    card["model"]["score_calibration"] = {"slope": -2.0, "offset": 0.0}
    (tmp_path / "detector.yaml").write_text(yaml.safe_dump(card))
    with pytest.raises(DetectorError, match="slope must be finite and > 0"):
        model_score_calibration(model)
    del card["model"]["score_calibration"]
    (tmp_path / "detector.yaml").write_text(yaml.safe_dump(card))
    assert model_score_calibration(model) is None


def test_write_card_calibration_round_trips(tmp_path):
    model = tmp_path / "detector.onnx"
    shutil.copy(MODEL, model)
    card = yaml.safe_load((ROOT / "assets/models/detector.yaml").read_text())
    del card["model"]["score_calibration"]
    (tmp_path / "detector.yaml").write_text(yaml.safe_dump(card))
    path = write_card_calibration(model, {"method": "platt", "slope": 3.0, "offset": -0.5}, "ocslam train-detector …")
    assert path == tmp_path / "detector.yaml"
    assert model_score_calibration(model) == ScoreCalibration(3.0, -0.5)
    again = yaml.safe_load(path.read_text())
    assert again["model"]["score_calibration"]["command"] == "ocslam train-detector …"
    assert again["model"]["sha256"] == card["model"]["sha256"]
    model.write_bytes(model.read_bytes() + b"\0")  # other weights: refused
    with pytest.raises(DetectorError, match="does not match its card"):
        write_card_calibration(model, {"slope": 1.0, "offset": 0.0})


# -- the soft decision ----------------------------------------------------------------------------------


def _ball_presence(mode: str, cal: ScoreCalibration | None, conf: float) -> float:
    cam = default_camera()
    ball = Cylinder(2.0, 0.05, 0.11, 0.0, 0.22)
    wall = Box(3.3, 0.0, 0.2, 6.0, 0.0, 0.0, 2.4)
    cfg = ConsciousnessConfig()
    cfg.mode = mode
    c = Consciousness(cfg, cam, cal)
    for i in range(6):
        T = Pose2(0.04 * i, 0.0, 0.0)
        scan = raycast([ball, wall], T, cam)
        c.update(detections([detection("ball", ball, T, cam, conf)], cam), scan, T, stamp=0.2 * i)
    (o,) = c.objects
    return o.presence


def test_soft_decision_reads_the_calibrated_probability_in_improved_mode():
    cal = ScoreCalibration(2.7, 0.93)  # an underconfident network (v4's card: 0.54 → 0.8)
    raw = _ball_presence("improved", None, 0.6)
    calibrated = _ball_presence("improved", cal, 0.6)
    assert raw == pytest.approx(0.6)  # never reaches the 80 % threshold on the raw score
    assert calibrated == pytest.approx(cal.probability(0.6))
    assert calibrated >= 0.8


def test_seed_mode_reads_the_raw_score_as_the_paper():
    assert _ball_presence("seed", ScoreCalibration(2.7, 0.93), 0.6) == pytest.approx(0.6)


# -- the command ----------------------------------------------------------------------------------------


def test_train_detector_score_calibration_writes_the_card(tmp_path, capsys):
    import argparse

    from test_detector_bench import _test_render_dataset

    from app.commands import train_detector

    data = _test_render_dataset(tmp_path / "data")
    (data / "data.yaml").write_text(yaml.safe_dump({"val": "images/val", "ocslam": {"seed": 7, "command": "test renders"}}))
    model = tmp_path / "m" / "detector.onnx"
    model.parent.mkdir()
    shutil.copy(MODEL, model)
    card = yaml.safe_load((ROOT / "assets/models/detector.yaml").read_text())
    del card["model"]["score_calibration"]
    (model.parent / "detector.yaml").write_text(yaml.safe_dump(card))
    p = argparse.ArgumentParser()
    train_detector.add_arguments(p)
    args = p.parse_args(["--score-calibration", str(data), "--app-model", str(model)])
    rc = train_detector.run(args)
    out, err = capsys.readouterr()
    assert rc == 0, err
    assert "score calibration of detector.onnx" in out
    entry = yaml.safe_load((model.parent / "detector.yaml").read_text())["model"]["score_calibration"]
    assert entry["fitted_on"]["images"] == 11 and entry["fitted_on"]["seed"] == 7
    assert entry["fitted_on"]["boxes"] >= 20 and model_score_calibration(model) is not None
    # no dataset there: one clear line, nothing written
    args = p.parse_args(["--score-calibration", str(tmp_path / "nothing"), "--app-model", str(model)])
    assert train_detector.run(args) == 2
    assert "no dataset (data.yaml)" in capsys.readouterr().err
