"""The model hash check (issue 12 item 4): a model file must be the one its card describes."""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import pytest
import yaml

import app.ocslam.detector as detmod
from app.ocslam.config import DetectorConfig
from app.ocslam.detector import Detector, DetectorError, file_sha256, find_model_card, verify_model_hash

ROOT = Path(__file__).resolve().parents[1]
MODELS = ROOT / "assets" / "models"
MODEL = MODELS / "detector.onnx"
CARD = MODELS / "detector.yaml"


def _flip_middle_byte(p: Path) -> None:
    b = bytearray(p.read_bytes())
    b[len(b) // 2] ^= 0xFF
    p.write_bytes(bytes(b))


def _copy_with_card(tmp: Path) -> tuple[Path, Path]:
    shutil.copyfile(MODEL, tmp / MODEL.name)
    shutil.copyfile(CARD, tmp / CARD.name)
    return tmp / MODEL.name, tmp / CARD.name


def test_every_committed_model_matches_its_card() -> None:
    models = sorted(MODELS.glob("*.onnx"))
    assert MODEL in models
    for m in models:
        found = find_model_card(m)
        assert found is not None, f"no card describes {m.name}"
        assert found[1]["sha256"] == hashlib.sha256(m.read_bytes()).hexdigest()
        assert verify_model_hash(m) == found[1]["sha256"]
    assert Detector(DetectorConfig(), MODEL).sha256 == file_sha256(MODEL)


def test_flipped_bytes_are_refused_naming_both_hashes(tmp_path: Path) -> None:
    model, card = _copy_with_card(tmp_path)
    expected = yaml.safe_load(card.read_text())["model"]["sha256"]
    _flip_middle_byte(model)
    actual = hashlib.sha256(model.read_bytes()).hexdigest()
    assert model.stat().st_size == MODEL.stat().st_size and actual != expected
    with pytest.raises(DetectorError) as e:
        Detector(DetectorConfig(), model)
    msg = str(e.value)
    assert "\n" not in msg
    assert actual in msg and expected in msg and str(model) in msg and "verify_hash: false" in msg
    # The opt-out loads the same file (it parses: the flipped byte is inside a weight tensor).
    det = Detector(DetectorConfig(verify_hash=False), model)
    assert det.sha256 is None


def test_a_card_of_another_model_is_refused(tmp_path: Path) -> None:
    model, card = _copy_with_card(tmp_path)
    d = yaml.safe_load(card.read_text())
    d["model"]["sha256"] = "0" * 64
    card.write_text(yaml.safe_dump(d))
    with pytest.raises(DetectorError, match="0{64}"):
        Detector(DetectorConfig(), model)
    d["model"]["sha256"] = None
    card.write_text(yaml.safe_dump(d))
    with pytest.raises(DetectorError, match="gives no sha256"):
        verify_model_hash(model)


def test_card_found_by_file_name_among_variants(tmp_path: Path) -> None:
    shutil.copyfile(MODEL, tmp_path / "other.onnx")
    (tmp_path / "cards.yaml").write_text(
        yaml.safe_dump({"model": {"file": "x.onnx", "sha256": "1" * 64},
                        "variants": [{"file": "other.onnx", "sha256": file_sha256(MODEL)}]})
    )
    (tmp_path / "junk.yaml").write_bytes(b"\xff\xfe: [")  # unreadable cards describe nothing
    card, entry = find_model_card(tmp_path / "other.onnx")
    assert card.name == "cards.yaml" and entry["file"] == "other.onnx"
    assert verify_model_hash(tmp_path / "other.onnx") == file_sha256(MODEL)


def test_uncarded_models(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # Outside assets/models a model without a card has nothing to be checked against: it loads.
    shutil.copyfile(MODEL, tmp_path / "mine.onnx")
    assert verify_model_hash(tmp_path / "mine.onnx") is None
    # In the models folder every model must be described.
    monkeypatch.setattr(detmod, "MODELS_DIR", tmp_path.resolve())
    with pytest.raises(DetectorError, match="not described by any model card"):
        Detector(DetectorConfig(), tmp_path / "mine.onnx")
    assert Detector(DetectorConfig(verify_hash=False), tmp_path / "mine.onnx").sha256 is None


def test_verify_hash_is_a_config_field() -> None:
    from app.config import Config

    cfg = Config()
    assert cfg.detector.verify_hash is True
    cfg.set("detector.verify_hash", False)
    assert cfg.detector.verify_hash is False


def test_a_card_is_parsed_once_and_read_again_when_it_changes(tmp_path: Path) -> None:
    # A sweep asks for the card's calibration once per replayed trace: the parse is kept while the file is
    # unchanged, each caller gets its own copy, and an edited card is read again.
    model = tmp_path / "m.onnx"
    model.write_bytes(b"weights")
    card = tmp_path / "m.yaml"
    card.write_text(yaml.safe_dump({"model": {"file": "m.onnx", "sha256": "a" * 64}}))
    first = find_model_card(model)
    assert first is not None and first[1]["sha256"] == "a" * 64
    first[1]["sha256"] = "mutated by a caller"
    assert find_model_card(model)[1]["sha256"] == "a" * 64
    card.write_text(yaml.safe_dump({"model": {"file": "m.onnx", "sha256": "b" * 64, "note": "edited"}}))
    assert find_model_card(model)[1]["sha256"] == "b" * 64
    card.write_text("[1, 2]")  # no longer a mapping: it describes nothing
    assert find_model_card(model) is None
