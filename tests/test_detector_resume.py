"""`train-detector --resume` continues one run (optimizer, LR schedule, epoch counter) for one more epoch.

A tiny synthetic dataset, 64 px, two epochs split over two sessions. Needs the [train] extra (skipped
without ultralytics)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.test_detector_training import _tiny_dataset

pytestmark = [pytest.mark.train, pytest.mark.slow]


def _opts(tmp: Path, data: Path, **kw):
    from app.training.train import TrainOptions

    return TrainOptions(
        data=data, imgsz=64, epochs=2, hours=None, batch=4, workers=0, cache=False,
        out_model=tmp / "model" / "det.onnx", runs_dir=tmp / "runs", config_dir=tmp / "yolo",
        checkpoint=tmp / "model" / "detector-train.pt", fp16_weights=False, **kw,
    )


def _lr_rows(run: Path) -> list[dict[str, float]]:
    from app.training.train import _metrics_from_csv

    return _metrics_from_csv(run / "results.csv")[0]


def test_resume_continues_the_same_run_for_one_more_epoch(tmp_path: Path) -> None:
    pytest.importorskip("ultralytics")
    import torch

    from app.training.train import train_detector

    data = _tiny_dataset(tmp_path / "data")
    first = train_detector(_opts(tmp_path, data, session_epochs=1), log=lambda *_: None)
    ck = tmp_path / "model" / "detector-train.pt"
    saved = torch.load(str(ck), map_location="cpu", weights_only=False)
    assert saved["epoch"] == 0 and saved["optimizer"] is not None  # one epoch of two, resumable
    moments = [v for st in saved["optimizer"]["state"].values() for k, v in st.items() if k != "step"]
    assert moments and all(v.dtype == torch.bfloat16 for v in moments)  # compact, float32's range
    assert ck.stat().st_size < 20e6
    assert first.epochs_done == 1
    rows1 = _lr_rows(tmp_path / "runs" / "train")
    assert [int(r["epoch"]) for r in rows1] == [1]

    second = train_detector(_opts(tmp_path, data, resume=True), log=lambda *_: None)
    assert second.start_epoch == 1  # the epoch counter went on
    rows = _lr_rows(tmp_path / "runs" / "train")
    assert [int(r["epoch"]) for r in rows] == [1, 2]  # the same run's results.csv, one more row
    # The LR schedule went on (warm-up continues) instead of restarting at its first value.
    assert rows[1]["lr/pg0"] != pytest.approx(rows1[0]["lr/pg0"])
    resumed = torch.load(str(ck), map_location="cpu", weights_only=False)
    assert resumed["epoch"] == 1 and resumed["optimizer"] is not None
    assert resumed["train_args"]["epochs"] == 2
    assert second.model_path.exists() and second.card["training"]["epochs_run"] == 2


def test_resume_without_a_checkpoint_is_a_clear_error(tmp_path: Path) -> None:
    pytest.importorskip("ultralytics")
    from app.training.train import train_detector

    data = _tiny_dataset(tmp_path / "data")
    with pytest.raises(FileNotFoundError, match="no checkpoint"):
        train_detector(_opts(tmp_path, data, resume=True), log=lambda *_: None)


def test_resume_on_other_data_restarts_the_best_epoch_but_keeps_the_run(tmp_path: Path) -> None:
    """Resumed with another dataset (e.g. ``--data A --data B``), the saved best fitness and early-stopping
    state are dropped (validation figures of other data are not comparable); the weights, optimizer
    and epoch counter are kept. Resumed with the same data, everything is kept."""
    torch = pytest.importorskip("torch")
    from app.training.train import _resume_checkpoint

    a = _tiny_dataset(tmp_path / "a")
    b = _tiny_dataset(tmp_path / "b")
    ck = tmp_path / "model" / "detector-train.pt"
    ck.parent.mkdir(parents=True)
    saved = {"epoch": 4, "optimizer": {"state": {}, "param_groups": []}, "best_fitness": 0.61,
             "stopper": {"best_fitness": 0.61, "best_epoch": 3},
             "train_args": {"data": str((a / "data.yaml").resolve()), "epochs": 10}}
    torch.save(saved, str(ck))
    same = torch.load(str(_resume_checkpoint(_opts(tmp_path, a, resume=True), a / "data.yaml", tmp_path / "runs")),
                      weights_only=False)
    assert same["best_fitness"] == 0.61 and same["stopper"]["best_epoch"] == 3
    other = torch.load(str(_resume_checkpoint(_opts(tmp_path, b, resume=True), b / "data.yaml", tmp_path / "runs")),
                       weights_only=False)
    assert other["best_fitness"] is None and other["stopper"] is None
    assert other["epoch"] == 4 and other["optimizer"] is not None
    assert other["train_args"]["data"] == str((b / "data.yaml").resolve()) and other["train_args"]["epochs"] == 10


def test_a_stretched_schedule_restarts_early_stopping_and_patience_can_be_changed(tmp_path: Path) -> None:
    """Stretching the schedule raises the learning rate again: the saved early-stopping state (best epoch long
    ago) would end the stretched run at once, so it starts again; ``--patience`` on resume replaces the saved."""
    torch = pytest.importorskip("torch")

    from app.training.train import _resume_checkpoint

    data = tmp_path / "data.yaml"
    data.write_text("path: .\ntrain: images/train\nval: images/val\nnames: {0: ball}\n")
    ck = tmp_path / "detector-train.pt"
    saved = {"epoch": 49, "optimizer": {"state": {}}, "best_fitness": 0.7,
             "stopper": {"best_fitness": 0.7, "best_epoch": 39},
             "train_args": {"data": str(data), "epochs": 60, "patience": 10}}
    torch.save(saved, str(ck))
    from dataclasses import replace

    same = _resume_checkpoint(replace(_opts(tmp_path, data, resume=True), checkpoint=ck, epochs=60), data, tmp_path / "runs")
    kept = torch.load(str(same), map_location="cpu", weights_only=False)
    assert kept["stopper"] == {"best_fitness": 0.7, "best_epoch": 39} and kept["train_args"]["patience"] == 10
    stretched = _resume_checkpoint(replace(_opts(tmp_path, data, resume=True), checkpoint=ck, epochs=80, patience=25),
                                   data, tmp_path / "runs")
    st = torch.load(str(stretched), map_location="cpu", weights_only=False)
    assert st["stopper"] is None and st["best_fitness"] == 0.7  # best.pt still only changes for a better epoch
    assert st["train_args"]["epochs"] == 80 and st["train_args"]["patience"] == 25


def test_a_resumed_run_takes_a_new_batch_size_and_keeps_the_rest(tmp_path: Path) -> None:
    """``--resume --batch 64`` (a GPU): the saved run's batch is replaced, the schedule and data are not."""
    torch = pytest.importorskip("torch")
    from dataclasses import replace

    from app.training.train import _resume_checkpoint

    data = tmp_path / "data.yaml"
    data.write_text("path: .\ntrain: images/train\nval: images/val\nnames: {0: ball}\n")
    ck = tmp_path / "detector-train.pt"
    torch.save({"epoch": 9, "optimizer": {"state": {}}, "train_args": {"data": str(data), "epochs": 20, "batch": 16}},
               str(ck))
    kept = _resume_checkpoint(replace(_opts(tmp_path, data, resume=True), checkpoint=ck, epochs=0), data, tmp_path / "r")
    assert torch.load(str(kept), weights_only=False)["train_args"]["batch"] == 16
    new = _resume_checkpoint(replace(_opts(tmp_path, data, resume=True), checkpoint=ck, epochs=0, resume_batch=64),
                             data, tmp_path / "r")
    ta = torch.load(str(new), weights_only=False)["train_args"]
    assert ta["batch"] == 64 and ta["epochs"] == 20 and ta["data"] == str(data.resolve())


def test_a_fitted_schedule_ends_within_the_sessions_budget(tmp_path: Path) -> None:
    """``--fit-schedule``: after the session's first epoch the schedule's end moves to the last epoch the
    budget holds (here far fewer than the 40 asked for), and the run stops there with its schedule complete."""
    pytest.importorskip("ultralytics")
    import torch

    from app.training.train import train_detector

    data = _tiny_dataset(tmp_path / "data")
    train_detector(_opts(tmp_path, data, session_epochs=1), log=lambda *_: None)
    lines: list[str] = []
    from dataclasses import replace

    opts = replace(_opts(tmp_path, data, resume=True, fit_schedule=True), epochs=40, hours=0.006)
    res = train_detector(opts, log=lines.append)
    fitted = [ln for ln in lines if ln.startswith("schedule fitted")]
    assert len(fitted) == 1 and "40 →" in fitted[0]
    end = int(fitted[0].split("→ ")[1].split()[0])
    assert 2 <= end < 40
    saved = torch.load(str(tmp_path / "model" / "detector-train.pt"), map_location="cpu", weights_only=False)
    assert saved["train_args"]["epochs"] == end  # the checkpoint carries the fitted schedule
    rows = _lr_rows(tmp_path / "runs" / "train")
    assert int(rows[-1]["epoch"]) == end  # it ran to the fitted end, not to 40
    assert res.card["training"]["epochs_max"] == end


def test_resumed_optimizer_state_takes_its_parameters_dtype_and_device() -> None:
    """The committed checkpoint stores Adam's moments as bfloat16 on the CPU; before the first step they
    become the parameters' float32 (CUDA's fused AdamW refuses a mix), the step counters stay."""
    torch = pytest.importorskip("torch")
    from types import SimpleNamespace

    from app.training.train import TrainOptions, _add_session_callbacks

    p = torch.nn.Parameter(torch.zeros(3))
    opt = torch.optim.AdamW([p], fused=False)
    opt.state[p] = {"step": torch.tensor(5.0), "exp_avg": torch.ones(3, dtype=torch.bfloat16),
                    "exp_avg_sq": torch.ones(3, dtype=torch.bfloat16)}
    opt.param_groups[0]["fused"] = True
    callbacks: dict = {}
    model = SimpleNamespace(add_callback=lambda name, fn: callbacks.setdefault(name, fn))
    _add_session_callbacks(model, TrainOptions(data=Path("d")), log=lambda *_: None)
    callbacks["on_train_start"](SimpleNamespace(optimizer=opt))
    st = opt.state[p]
    assert st["exp_avg"].dtype == torch.float32 and st["exp_avg_sq"].dtype == torch.float32
    assert st["step"].item() == 5.0 and opt.param_groups[0]["fused"] is False
    p.grad = torch.ones(3)
    opt.step()  # steps with the restored moments
