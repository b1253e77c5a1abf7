"""Train the YOLO detector from scratch on an ``ocslam dataset`` (a thin wrapper around ultralytics).

Needs the optional ``[train]`` extra (torch, torchvision, ultralytics, onnx, onnxslim); ultralytics is
AGPL-3.0, so it is imported here only, lazily, and never by the runtime.

Fully offline: ``YOLO_OFFLINE=1`` and ``YOLO_AUTOINSTALL=false``, a private ``YOLO_CONFIG_DIR`` with a
local TTF font in place of the ``Arial.ttf`` ultralytics would download, the network built from its
``yolov8n.yaml`` with ``pretrained=False`` (naming a ``.pt`` would start a download), plots off.

The result is exported to ONNX (``[1, 4 + C, N]`` output, dynamic input size) and written with its model
card (``detector.yaml``: classes, input size, the dataset's command and seed, epochs, training time,
validation metrics, date). The app's static int8 model is made from it by :mod:`app.training.optimize`.
"""

from __future__ import annotations

import datetime as _dt
import os
import platform
import shutil
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from app.config import PROJECT_ROOT, atomic_write_bytes, atomic_write_text, project_relative
from app.ocslam.detector import file_sha256, input_shape_for
from app.ocslam.messages import CLASS_NAMES
from app.training.optimize import compress_weights_fp16

__all__ = ["TrainOptions", "TrainResult", "setup_offline", "train_detector", "TrainingUnavailable"]

MISSING_EXTRA = (
    "training needs the optional [train] extra (torch, torchvision, ultralytics, onnx, onnxslim): "
    "pip install -e '.[train]'   (or: make train)"
)


class TrainingUnavailable(RuntimeError):
    """ultralytics (the ``[train]`` extra) is not installed."""


@dataclass
class TrainOptions:
    """Everything ``ocslam train-detector`` passes to ultralytics."""

    data: Path
    model: str = "yolov8n.yaml"
    imgsz: int = 224
    epochs: int = 60
    hours: float | None = 1.0
    batch: int = 16
    resume_batch: int | None = None  # with resume: a new batch size (ultralytics accumulates to nbs=64 either way)
    patience: int | None = None  # None: DEFAULT_PATIENCE for a new run, the saved run's on --resume
    workers: int = 2
    seed: int = 0
    cache: bool = True
    close_mosaic: int = 10
    out_model: Path = field(default_factory=lambda: PROJECT_ROOT / "assets" / "models" / "detector.onnx")
    out_card: Path | None = None  # default: out_model with .yaml
    runs_dir: Path = field(default_factory=lambda: PROJECT_ROOT / "runs" / "detector")
    name: str = "train"
    config_dir: Path = field(default_factory=lambda: PROJECT_ROOT / ".yolo")
    init_weights: Path | None = None  # start from one of our own earlier checkpoints (never a download)
    fp16_weights: bool = True  # store weights as float16 in the ONNX file (half the size, same inference)
    resume: bool = False  # continue the run saved in `checkpoint` (optimizer, LR schedule, epoch counter)
    checkpoint: Path | None = None  # resumable copy of every epoch's last.pt (the command: assets/models/detector-train.pt)
    session_epochs: int | None = None  # stop this session after this many epochs (the schedule stays the run's)
    extra: dict[str, Any] = field(default_factory=dict)  # further ultralytics train() arguments
    fit_schedule: bool = False  # with resume + hours: end the schedule at the last epoch the budget holds
    device: str = "cpu"  # torch device: "cpu" or a CUDA index ("0"); the schedule and the data do not depend on it


@dataclass
class TrainResult:
    model_path: Path
    card_path: Path
    card: dict[str, Any]
    start_epoch: int = 0  # first epoch (0-based) trained in this session
    epochs_done: int = 0  # epochs completed by the run so far (all sessions)
    checkpoint: Path | None = None


#: epochs without a better validation mAP before a new run stops (``--patience``)
DEFAULT_PATIENCE = 15


def _same_data(saved: Any, data_yaml: Path) -> bool:
    """True if a checkpoint's ``data`` (path of its data file) names ``data_yaml`` or a file with the same text."""
    if not saved:
        return False
    old = Path(str(saved))
    try:
        return old.resolve() == data_yaml.resolve() or old.read_text() == data_yaml.read_text()
    except OSError:
        return False


def _resume_checkpoint(opts: TrainOptions, data_yaml: Path, runs_dir: Path) -> Path:
    """Prepare ``opts.checkpoint`` for ultralytics' ``resume``: a copy in this machine's run folder whose
    saved arguments point at this dataset and folder, with ``epochs`` raised to ``opts.epochs`` when
    that extends the schedule (one long schedule: the same LR curve, stretched only on request)."""
    import torch

    ck = Path(opts.checkpoint) if opts.checkpoint else None
    if ck is None or not ck.is_file():
        raise FileNotFoundError(f"--resume: no checkpoint at {ck} (a run writes one every epoch with --checkpoint)")
    ckpt = torch.load(str(ck), map_location="cpu", weights_only=False)
    if not isinstance(ckpt, dict) or ckpt.get("optimizer") is None or int(ckpt.get("epoch", -1)) < 0:
        raise ValueError(f"--resume: {ck} is not a resumable checkpoint (no optimizer state or epoch counter)")
    ta = dict(ckpt.get("train_args") or {})
    if not _same_data(ta.get("data"), data_yaml):
        # other data: its validation figures are not comparable with the saved best, so the best epoch and
        # early stopping start again (the weights, optimizer and learning-rate schedule go on)
        ckpt["best_fitness"], ckpt["stopper"] = None, None
    save_dir = runs_dir / opts.name
    ta.update(data=str(data_yaml.resolve()), project=str(runs_dir), name=opts.name, save_dir=str(save_dir),
              exist_ok=True, device=opts.device, workers=opts.workers, cache=opts.cache, time=None, plots=False)
    if opts.epochs and int(opts.epochs) > int(ta.get("epochs", 0)):
        ta["epochs"] = int(opts.epochs)
        # a stretched schedule raises the learning rate again, so the next epochs are worse for a while: early
        # stopping counts from here (the best weights and best.pt still only change for a better epoch)
        ckpt["stopper"] = None
    if opts.patience is not None:
        ta["patience"] = int(opts.patience)
    if opts.resume_batch is not None:
        # the optimizer steps on a nominal batch of `nbs` images (gradients accumulated up to it), so a larger
        # batch on a GPU keeps the run's step size and schedule; only BatchNorm sees other batch statistics
        ta["batch"] = int(opts.resume_batch)
    ckpt["train_args"] = ta
    last = save_dir / "weights" / "last.pt"
    last.parent.mkdir(parents=True, exist_ok=True)
    torch.save(ckpt, str(last))
    return last


def setup_offline(config_dir: Path) -> None:
    """Environment that keeps ultralytics off the network. Call before importing ultralytics."""
    config_dir = Path(config_dir)
    (config_dir / "Ultralytics").mkdir(parents=True, exist_ok=True)
    os.environ["YOLO_OFFLINE"] = "1"
    os.environ["YOLO_AUTOINSTALL"] = "false"
    os.environ["YOLO_CONFIG_DIR"] = str(config_dir)
    font = config_dir / "Ultralytics" / "Arial.ttf"
    if not font.exists():
        src = _find_font()
        if src is not None:
            shutil.copyfile(src, font)


def _find_font() -> Path | None:
    try:
        import matplotlib

        p = Path(matplotlib.get_data_path()) / "fonts" / "ttf" / "DejaVuSans.ttf"
        if p.exists():
            return p
    except ImportError:
        pass
    for cand in ("/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf", "/usr/share/fonts/TTF/DejaVuSans.ttf"):
        if Path(cand).exists():
            return Path(cand)
    return None


def _import_yolo():
    try:
        from ultralytics import YOLO  # noqa: F401
    except ImportError as e:
        raise TrainingUnavailable(f"{MISSING_EXTRA} ({e})") from None
    return YOLO


def _data_yaml(data: Path) -> Path:
    data = Path(data)
    y = data / "data.yaml" if data.is_dir() else data
    if not y.is_file():
        raise FileNotFoundError(f"no YOLO dataset at {data} (expected {y}); make one with: ocslam dataset --out {data}")
    d = yaml.safe_load(y.read_text())
    names = d.get("names")
    if isinstance(names, dict):
        names = [names[k] for k in sorted(names)]
    if tuple(names or ()) != CLASS_NAMES:
        raise ValueError(f"{y}: classes {names} differ from the detector's {list(CLASS_NAMES)}")
    return y


def combine_datasets(datasets: list[Path], out_yaml: Path) -> Path:
    """One ultralytics data file training on the union of several ``ocslam dataset`` folders (their
    train and val images, by absolute path); its ``ocslam`` block lists each dataset's recipe and counts
    (the model card's lineage). Returns ``out_yaml``."""
    trains, vals, parts = [], [], []
    for d in datasets:
        y = _data_yaml(d)
        meta = yaml.safe_load(y.read_text())
        root = Path(meta["path"]).resolve() if meta.get("path") else y.parent.resolve()
        trains.append(str(root / meta.get("train", "images/train")))
        vals.append(str(root / meta.get("val", "images/val")))
        o = meta.get("ocslam", {}) or {}
        parts.append({"path": str(d), **{k: o.get(k) for k in ("command", "seed", "images", "families", "train_worlds", "val_worlds")}})
    images = {s: sum(int((p.get("images") or {}).get(s, 0)) for p in parts) for s in ("train", "val")}
    data = {
        "train": trains,
        "val": vals,
        "nc": len(CLASS_NAMES),
        "names": dict(enumerate(CLASS_NAMES)),
        "ocslam": {
            "command": " + ".join(str(p["command"]) for p in parts),
            "seed": [p.get("seed") for p in parts],
            "images": images,
            "train_worlds": [w for p in parts for w in (p.get("train_worlds") or [])],
            "val_worlds": [w for p in parts for w in (p.get("val_worlds") or [])],
            "datasets": parts,
        },
    }
    out_yaml.parent.mkdir(parents=True, exist_ok=True)
    out_yaml.write_text("# the union of several `ocslam dataset` folders (ocslam train-detector --data A --data B)\n"
                        + yaml.safe_dump(data, sort_keys=False))
    return out_yaml


def _metrics_from_csv(csv_path: Path) -> tuple[list[dict[str, float]], dict[str, float] | None]:
    """Rows of ultralytics' results.csv and the best row by mAP50-95 (its fitness)."""
    if not csv_path.exists():
        return [], None
    lines = [ln for ln in csv_path.read_text().splitlines() if ln.strip()]
    head = [h.strip() for h in lines[0].split(",")]
    rows = []
    for ln in lines[1:]:
        vals = ln.split(",")
        try:
            rows.append({h: float(v) for h, v in zip(head, vals)})
        except ValueError:
            continue
    key = "metrics/mAP50-95(B)"
    best = max(rows, key=lambda r: r.get(key, -1.0)) if rows else None
    return rows, best


def train_detector(opts: TrainOptions, log=print) -> TrainResult:
    """Train, validate, export ONNX and write the model and its card. Returns where they went."""
    setup_offline(opts.config_dir)
    YOLO = _import_yolo()

    data_yaml = _data_yaml(opts.data)
    dataset_meta = yaml.safe_load(data_yaml.read_text()).get("ocslam", {})
    runs_dir = Path(opts.runs_dir).resolve()
    if opts.resume:
        last = _resume_checkpoint(opts, data_yaml, runs_dir)
        model = YOLO(str(last), task="detect")
        args: dict[str, Any] = dict(resume=str(last))
    else:
        model = YOLO(opts.model, task="detect")
        args = _fresh_args(opts, data_yaml, runs_dir)
    _add_session_callbacks(model, opts, log)
    log(f"{'resuming ' + str(last) if opts.resume else 'training ' + opts.model} on {data_yaml} at {opts.imgsz} px "
        f"({_device_text(opts.device)})")
    t0 = time.monotonic()
    model.train(**args)
    train_s = time.monotonic() - t0
    return _finish(model, opts, data_yaml, dataset_meta, train_s, log)


def _architecture(trainer: Any, default: str) -> str:
    """The trained network's name: its model yaml's (a resumed run's ``opts.model`` is only the default)."""
    model = getattr(trainer, "model", None)
    y = getattr(getattr(model, "module", model), "yaml", None)
    name = y.get("yaml_file") if isinstance(y, dict) else None
    return Path(str(name or default)).stem


def _device_text(device: str) -> str:
    """The training device in words, for the log and the model card."""
    import torch

    if device != "cpu" and torch.cuda.is_available():
        return f"cuda:{device} ({torch.cuda.get_device_name(int(device.split(',')[0]))}, {os.cpu_count()} CPU cores for data)"
    return f"cpu ({platform.processor() or platform.machine()}, {os.cpu_count()} cores, {torch.get_num_threads()} threads)"


def _fresh_args(opts: TrainOptions, data_yaml: Path, runs_dir: Path) -> dict[str, Any]:
    args: dict[str, Any] = dict(
        data=str(data_yaml.resolve()),
        imgsz=opts.imgsz,
        epochs=opts.epochs,
        batch=opts.batch,
        patience=DEFAULT_PATIENCE if opts.patience is None else int(opts.patience),
        workers=opts.workers,
        seed=opts.seed,
        device=opts.device,
        pretrained=False,
        plots=False,
        amp=False,
        cache=opts.cache,
        close_mosaic=opts.close_mosaic,
        project=str(runs_dir),
        name=opts.name,
        exist_ok=True,
        deterministic=False,
        verbose=True,
    )
    if opts.init_weights:
        w = Path(opts.init_weights)
        if not w.is_file():
            raise FileNotFoundError(f"no checkpoint at {w}")
        args["pretrained"] = str(w.resolve())  # ultralytics loads matching weights from this local file
    if opts.hours and opts.checkpoint is None:
        args["time"] = float(opts.hours)  # ultralytics fits the epochs (and the LR schedule) to the budget
    args.update(opts.extra)
    return args


def compact_checkpoint(last: Path) -> bytes:
    """ultralytics' ``last.pt`` with the optimizer's moment buffers stored as bfloat16 (float32's range,
    so Adam's tiny second moments do not flush to zero as in float16): 30 → 18 MB for yolov8n with
    AdamW. ``torch.optim.Optimizer.load_state_dict`` casts them back to the parameters' float32 on
    resume; the step counters stay as they are."""
    import io

    import torch

    ckpt = torch.load(str(last), map_location="cpu", weights_only=False)
    opt = ckpt.get("optimizer")
    if isinstance(opt, dict):
        for st in opt.get("state", {}).values():
            for k, v in list(st.items()):
                if k != "step" and torch.is_tensor(v) and v.is_floating_point() and v.dtype == torch.float32:
                    st[k] = v.to(torch.bfloat16)
    buf = io.BytesIO()
    torch.save(ckpt, buf)
    return buf.getvalue()


def _add_session_callbacks(model: Any, opts: TrainOptions, log) -> None:
    """Copy every epoch's resumable ``last.pt`` to ``opts.checkpoint`` (before ultralytics strips the
    optimizer from it at the end), and end the session cleanly after ``opts.session_epochs`` epochs or,
    for a resumable run, ``opts.hours`` hours (the schedule is left as it is, so the next --resume
    continues it)."""
    t_start = time.monotonic()
    state = {"epochs": 0}

    def on_model_save(trainer) -> None:
        if opts.checkpoint is None:
            return
        last = Path(trainer.last)
        if last.is_file():
            atomic_write_bytes(Path(opts.checkpoint), compact_checkpoint(last))

    def on_fit_epoch_end(trainer) -> None:
        state["epochs"] += 1
        per_epoch = (time.monotonic() - t_start) / state["epochs"]
        if opts.fit_schedule and opts.hours:
            # a lease of fixed length (a lent GPU machine): after the first epoch, the schedule's end moves to the
            # last epoch that fits, so its learning rate anneals fully within the lease (the linear LR curve reads
            # trainer.epochs at every step); later epochs are timed like this one, data set-up excluded
            per_epoch = max(float(getattr(trainer, "epoch_time", 0.0) or 0.0), 1e-3) * 1.05
            if state["epochs"] == 1:
                left = opts.hours * 3600 - (time.monotonic() - t_start)
                end = trainer.epoch + 1 + max(int(left // per_epoch), 0)
                if end != trainer.epochs:
                    log(f"schedule fitted to the session's budget: {trainer.epochs} → {end} epochs "
                        f"({per_epoch:.1f} s an epoch)")
                    trainer.epochs = trainer.args.epochs = end
                if end <= trainer.epoch + 1:
                    trainer.stop = True
        st = getattr(trainer, "stopper", None)  # ultralytics' early stopping: no better epoch for `patience` epochs
        early = st is not None and bool(st.patience) and trainer.epoch + 1 - int(st.best_epoch) >= int(st.patience)
        if opts.session_epochs is not None and state["epochs"] >= opts.session_epochs:
            trainer.stop = True
        elif opts.checkpoint is not None and opts.hours and time.monotonic() - t_start + per_epoch > opts.hours * 3600:
            trainer.stop = True
        if trainer.stop and trainer.epoch + 1 < trainer.epochs:
            why = (f"early stopping: no better epoch in the last {st.patience if st is not None else '?'} (raise it "
                   "with --resume --patience N)" if early else "the session's budget")
            log(f"session ends after epoch {trainer.epoch + 1} of {trainer.epochs} ({why}); continue with --resume")

    def on_train_start(trainer) -> None:
        # A resumed optimizer: torch casts the moment buffers (bfloat16 in the committed checkpoint) to their
        # parameters' dtype and device, but leaves the step counters where the saved run kept them (the CPU)
        # unless the *saved* groups were fused. CUDA's fused AdamW, which ultralytics picks on a GPU, refuses
        # that mix; its multi-tensor path takes it, and the buffers are made to match here in any case.
        opt = getattr(trainer, "optimizer", None)
        if opt is None:
            return
        for p, st in opt.state.items():
            for k, v in list(st.items()):
                if k != "step" and hasattr(v, "is_floating_point") and v.is_floating_point():
                    st[k] = v.to(device=p.device, dtype=p.dtype)
        for g in opt.param_groups:
            if g.get("fused"):
                g["fused"] = False

    model.add_callback("on_train_start", on_train_start)
    model.add_callback("on_model_save", on_model_save)
    model.add_callback("on_fit_epoch_end", on_fit_epoch_end)


def _finish(model: Any, opts: TrainOptions, data_yaml: Path, dataset_meta: dict, train_s: float, log) -> TrainResult:
    import torch

    YOLO = _import_yolo()

    trainer = model.trainer
    save_dir = Path(trainer.save_dir)
    best_pt = save_dir / "weights" / "best.pt"
    if not best_pt.exists():
        best_pt = save_dir / "weights" / "last.pt"
    rows, best_row = _metrics_from_csv(save_dir / "results.csv")
    targs = getattr(trainer, "args", None)
    try:  # the exported weights' own epoch: the last row with their validation figures (a run resumed on
        # other data has rows of two validation sets, so the best row of the file is not theirs)
        tm = (torch.load(str(best_pt), map_location="cpu", weights_only=False) or {}).get("train_metrics") or {}
        key = "metrics/mAP50-95(B)"
        mine = [r for r in rows if key in tm and abs(r.get(key, -1.0) - float(tm[key])) < 5e-6]
        if mine:
            best_row = mine[-1]
    except Exception:  # noqa: BLE001 - the card falls back to the file's best row
        pass

    # Final validation of the best weights (ultralytics also does this at the end of train()).
    final = getattr(trainer, "metrics", None) or {}
    log(f"exporting {best_pt} to ONNX")
    exported = Path(
        YOLO(str(best_pt), task="detect").export(
            format="onnx", imgsz=opts.imgsz, dynamic=True, simplify=True, nms=False, batch=1
        )
    )
    out_model = Path(opts.out_model)
    out_card = Path(opts.out_card) if opts.out_card else out_model.with_suffix(".yaml")
    if opts.fp16_weights:
        small = exported.with_name(exported.stem + "_fp16w.onnx")
        compress_weights_fp16(exported, small)
        exported = small
    atomic_write_bytes(out_model, exported.read_bytes())

    def fnum(x: Any) -> float | None:
        try:
            return round(float(x), 4)
        except (TypeError, ValueError):
            return None

    card: dict[str, Any] = {
        "model": {
            "file": out_model.name,
            "architecture": _architecture(trainer, opts.model),
            "format": "onnx, output [1, 4 + classes, N] (cx, cy, w, h, class scores), dynamic input"
            + (", weights stored as float16 (computed in float32)" if opts.fp16_weights else ""),
            "size_bytes": out_model.stat().st_size,
            "sha256": file_sha256(out_model),
            "pretrained": False,
        },
        "classes": list(CLASS_NAMES),
        "input": {
            "width": opts.imgsz,
            "camera_640x480": list(input_shape_for(640, 480, opts.imgsz)),
            "note": "images keep their aspect: width = input width, height letterboxed up to a multiple of 32",
        },
        "dataset": {
            "path": project_relative(opts.data),
            "command": dataset_meta.get("command"),
            "parts": [{"path": project_relative(p["path"]) if p.get("path") else None,
                       **{k: p.get(k) for k in ("command", "seed", "images", "families")}}
                      for p in dataset_meta.get("datasets", [])] or None,
            "seed": dataset_meta.get("seed"),
            "images": dataset_meta.get("images"),
            "train_worlds": dataset_meta.get("train_worlds"),
            "val_worlds": dataset_meta.get("val_worlds"),
        },
        "training": {
            "command": " ".join(["ocslam", "train-detector", *sys.argv[2:]]) if sys.argv[1:2] == ["train-detector"] else None,
            "epochs_run": len(rows),
            "epochs_max": int(getattr(trainer, "epochs", opts.epochs)),
            "best_epoch": int(best_row["epoch"]) if best_row else None,
            "imgsz": opts.imgsz,
            "batch": int(getattr(targs, "batch", None) or opts.batch),
            "patience": int(getattr(targs, "patience", None) or opts.patience or DEFAULT_PATIENCE),
            "overrides": dict(opts.extra) or None,
            "time_budget_h": opts.hours,
            "initialised_from": project_relative(opts.init_weights) if opts.init_weights
            else (f"{project_relative(targs.pretrained)} (the run's start; resumed)" if opts.resume and isinstance(getattr(targs, "pretrained", None), str)
                  else "random (from the model yaml)"),
            "training_time_h": round(train_s / 3600.0, 3),
            "device": _device_text(opts.device),
            "torch": str(torch.__version__),
            "ultralytics": str(__import__("ultralytics").__version__),
        },
        "validation": {
            "split": "val (worlds not used for training)",
            "precision": fnum(final.get("metrics/precision(B)", best_row and best_row.get("metrics/precision(B)"))),
            "recall": fnum(final.get("metrics/recall(B)", best_row and best_row.get("metrics/recall(B)"))),
            "map50": fnum(final.get("metrics/mAP50(B)", best_row and best_row.get("metrics/mAP50(B)"))),
            "map50_95": fnum(final.get("metrics/mAP50-95(B)", best_row and best_row.get("metrics/mAP50-95(B)"))),
            "note": "ultralytics' validator (conf 0.001); `ocslam bench detector` measures held-out worlds at the app's threshold",
        },
        "date": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
    }
    atomic_write_text(out_card, "# Model card of the OCSLAM detector (written by `ocslam train-detector`)\n" + yaml.safe_dump(card, sort_keys=False))
    log(f"wrote {out_model} ({out_model.stat().st_size / 1e6:.1f} MB) and {out_card}")
    return TrainResult(out_model, out_card, card, start_epoch=int(getattr(trainer, "start_epoch", 0)),
                       epochs_done=len(rows), checkpoint=Path(opts.checkpoint) if opts.checkpoint else None)
