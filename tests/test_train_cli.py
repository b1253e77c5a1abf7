"""``ocslam train-detector``'s arguments and the union of datasets, without the [train] extra."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from app.ocslam.messages import CLASS_NAMES
from app.training.train import combine_datasets


def _dataset(root: Path, seed: int, n_train: int, n_val: int, with_path: bool = False) -> Path:
    for split in ("train", "val"):
        (root / "images" / split).mkdir(parents=True)
    meta = {
        "train": "images/train",
        "val": "images/val",
        "nc": len(CLASS_NAMES),
        "names": dict(enumerate(CLASS_NAMES)),
        "ocslam": {"command": f"ocslam dataset --seed {seed}", "seed": seed, "images": {"train": n_train, "val": n_val},
                   "families": ["rooms"], "train_worlds": [f"w{seed}a"], "val_worlds": [f"w{seed}b"]},
    }
    if with_path:
        meta["path"] = str(root)
    (root / "data.yaml").write_text(yaml.safe_dump(meta))
    return root


def test_combine_datasets_lists_both_folders_and_lineages(tmp_path: Path) -> None:
    a = _dataset(tmp_path / "a", 1, 10, 2)
    b = _dataset(tmp_path / "b", 2, 30, 4, with_path=True)
    y = combine_datasets([a, b], tmp_path / "run" / "data.yaml")
    d = yaml.safe_load(y.read_text())
    assert d["train"] == [str((a / "images/train").resolve()), str((b / "images/train").resolve())]
    assert d["val"] == [str((a / "images/val").resolve()), str((b / "images/val").resolve())]
    assert [d["names"][i] for i in range(len(CLASS_NAMES))] == list(CLASS_NAMES)
    o = d["ocslam"]
    assert o["images"] == {"train": 40, "val": 6}
    assert o["train_worlds"] == ["w1a", "w2a"] and o["val_worlds"] == ["w1b", "w2b"]
    assert o["command"] == "ocslam dataset --seed 1 + ocslam dataset --seed 2" and o["seed"] == [1, 2]
    assert [p["seed"] for p in o["datasets"]] == [1, 2]


def test_combine_datasets_refuses_other_classes(tmp_path: Path) -> None:
    a = _dataset(tmp_path / "a", 1, 1, 1)
    b = _dataset(tmp_path / "b", 2, 1, 1)
    meta = yaml.safe_load((b / "data.yaml").read_text())
    meta["names"] = {0: "cat"}
    (b / "data.yaml").write_text(yaml.safe_dump(meta))
    with pytest.raises(ValueError, match="classes"):
        combine_datasets([a, b], tmp_path / "c.yaml")


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--data", "{a}", "--data", "{missing}"], "no dataset (data.yaml) at"),
        (["--data", "{a}", "--lr0", "2"], "--lr0 must be in"),
        (["--data", "{a}", "--lr0", "0.002"], "--lr0 needs --optimizer"),
        (["--data", "{a}", "--lr0", "0.002", "--optimizer", "auto"], "--lr0 needs --optimizer"),
        (["--data", "{a}", "--warmup-epochs", "-1"], "--warmup-epochs must be in"),
        (["--data", "{a}", "--resume", "--lr0", "0.001", "--optimizer", "AdamW"], "--resume continues the saved run's schedule"),
        (["--data", "{a}", "--device", "cuda:zero"], "--device must be cpu or CUDA device indices"),
        (["--data", "{a}", "--batch", "0"], "--batch must be at least 1"),
        (["--data", "{a}", "--hours", "0", "--fit-schedule"], "--fit-schedule needs --hours"),
        (["--data", "{a}", "--resume", "--hours", "0", "--fit-schedule"], "--fit-schedule needs --hours"),
    ],
)
def test_bad_training_arguments_are_one_line_errors(tmp_path: Path, capsys, argv: list[str], message: str) -> None:
    from app.cli import main

    a = _dataset(tmp_path / "a", 1, 1, 1)
    argv = [s.format(a=a, missing=tmp_path / "nowhere") for s in argv]
    assert main(["train-detector", *argv, "--runs", str(tmp_path / "runs")]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


def test_same_data_is_the_same_file_or_the_same_text(tmp_path: Path) -> None:
    from app.training.train import _same_data

    a = _dataset(tmp_path / "a", 1, 1, 1)
    copy = tmp_path / "copy.yaml"
    copy.write_text((a / "data.yaml").read_text())
    b = _dataset(tmp_path / "b", 2, 1, 1)
    assert _same_data(str(a / "data.yaml"), a / "data.yaml")
    assert _same_data(str(copy), a / "data.yaml")  # another machine's path to the same dataset
    assert not _same_data(str(b / "data.yaml"), a / "data.yaml")
    assert not _same_data(str(tmp_path / "gone.yaml"), a / "data.yaml") and not _same_data(None, a / "data.yaml")


def test_a_new_run_never_overwrites_the_saved_runs_checkpoint(tmp_path: Path) -> None:
    from app.commands.train_detector import run_checkpoint

    default, run_dir = tmp_path / "assets" / "detector-train.pt", tmp_path / "runs" / "ft"
    assert run_checkpoint(None, False, default, run_dir) == default  # nothing saved yet: the committed place
    default.parent.mkdir(parents=True)
    default.write_bytes(b"a saved run")
    assert run_checkpoint(None, False, default, run_dir) == run_dir / "train.pt"  # a new run: its own folder
    assert run_checkpoint(None, True, default, run_dir) == default  # --resume continues the saved run
    assert run_checkpoint(tmp_path / "x.pt", False, default, run_dir) == tmp_path / "x.pt"  # named: the user's choice
