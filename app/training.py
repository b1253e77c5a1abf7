"""Train the YOLO detector from scratch on an ``ocslam dataset`` (a thin wrapper around ultralytics).

Needs the optional ``[train]`` extra (torch, torchvision, ultralytics, onnx, onnxslim); ultralytics is
AGPL-3.0, so it is imported here only, lazily, and never by the runtime.

Fully offline: ``YOLO_OFFLINE=1`` and ``YOLO_AUTOINSTALL=false``, a private ``YOLO_CONFIG_DIR`` with a
local TTF font in place of the ``Arial.ttf`` ultralytics would download, the network built from its
``yolov8n.yaml`` with ``pretrained=False`` (naming a ``.pt`` would start a download), plots off.

The result is exported to ONNX (``[1, 4 + C, N]`` output, dynamic input size) and written with its model
card (``detector.yaml``: classes, input size, the dataset's command and seed, epochs, training time,
validation metrics, date).
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import os
import platform
import shutil
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from app.config import PROJECT_ROOT, atomic_write_bytes, atomic_write_text
from app.ocslam.detector import input_shape_for
from app.ocslam.messages import CLASS_NAMES

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
    patience: int = 15
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
    extra: dict[str, Any] = field(default_factory=dict)  # further ultralytics train() arguments


@dataclass
class TrainResult:
    model_path: Path
    card_path: Path
    card: dict[str, Any]


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


def _sha256(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def compress_weights_fp16(src: Path, dst: Path, min_size: int = 1024) -> None:
    """Store the large float32 weights of an ONNX model as float16, each behind a ``Cast`` to float32.

    Halves the file; onnxruntime folds the casts when it loads the model, so inference still runs in
    float32 on the rounded weights (scores change by about 1e-4).
    """
    import numpy as np
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    m = onnx.load(str(src))
    g = m.graph
    halves, casts = [], []
    for init in list(g.initializer):
        if init.data_type != TensorProto.FLOAT:
            continue
        a = numpy_helper.to_array(init)
        if a.size < min_size:
            continue
        g.initializer.remove(init)
        halves.append(numpy_helper.from_array(a.astype(np.float16), init.name + "_fp16"))
        casts.append(helper.make_node("Cast", [init.name + "_fp16"], [init.name], to=TensorProto.FLOAT, name=init.name + "_cast"))
    g.initializer.extend(halves)
    for i, c in enumerate(casts):
        g.node.insert(i, c)
    onnx.checker.check_model(m)
    onnx.save(m, str(dst))


def train_detector(opts: TrainOptions, log=print) -> TrainResult:
    """Train, validate, export ONNX and write the model and its card. Returns where they went."""
    setup_offline(opts.config_dir)
    YOLO = _import_yolo()
    import torch

    data_yaml = _data_yaml(opts.data)
    dataset_meta = yaml.safe_load(data_yaml.read_text()).get("ocslam", {})
    runs_dir = Path(opts.runs_dir).resolve()
    model = YOLO(opts.model, task="detect")
    args: dict[str, Any] = dict(
        data=str(data_yaml.resolve()),
        imgsz=opts.imgsz,
        epochs=opts.epochs,
        batch=opts.batch,
        patience=opts.patience,
        workers=opts.workers,
        seed=opts.seed,
        device="cpu",
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
    if opts.hours:
        args["time"] = float(opts.hours)
    args.update(opts.extra)
    log(f"training {opts.model} on {data_yaml} at {opts.imgsz} px (CPU, {torch.get_num_threads()} threads)")
    t0 = time.monotonic()
    model.train(**args)
    train_s = time.monotonic() - t0
    trainer = model.trainer
    save_dir = Path(trainer.save_dir)
    best_pt = save_dir / "weights" / "best.pt"
    if not best_pt.exists():
        best_pt = save_dir / "weights" / "last.pt"
    rows, best_row = _metrics_from_csv(save_dir / "results.csv")

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
            "architecture": Path(opts.model).stem,
            "format": "onnx, output [1, 4 + classes, N] (cx, cy, w, h, class scores), dynamic input"
            + (", weights stored as float16 (computed in float32)" if opts.fp16_weights else ""),
            "size_bytes": out_model.stat().st_size,
            "sha256": _sha256(out_model),
            "pretrained": False,
        },
        "classes": list(CLASS_NAMES),
        "input": {
            "width": opts.imgsz,
            "camera_640x480": list(input_shape_for(640, 480, opts.imgsz)),
            "note": "images keep their aspect: width = input width, height letterboxed up to a multiple of 32",
        },
        "dataset": {
            "path": str(Path(opts.data)),
            "command": dataset_meta.get("command"),
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
            "batch": opts.batch,
            "patience": opts.patience,
            "time_budget_h": opts.hours,
            "initialised_from": str(opts.init_weights) if opts.init_weights else "random (from the model yaml)",
            "training_time_h": round(train_s / 3600.0, 3),
            "device": f"cpu ({platform.processor() or platform.machine()}, {os.cpu_count()} cores)",
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
    return TrainResult(out_model, out_card, card)
