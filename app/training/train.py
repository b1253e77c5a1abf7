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
    resume: bool = False  # continue the run saved in `checkpoint` (optimizer, LR schedule, epoch counter)
    checkpoint: Path | None = None  # resumable copy of every epoch's last.pt (the command: assets/models/detector-train.pt)
    session_epochs: int | None = None  # stop this session after this many epochs (the schedule stays the run's)
    extra: dict[str, Any] = field(default_factory=dict)  # further ultralytics train() arguments


@dataclass
class TrainResult:
    model_path: Path
    card_path: Path
    card: dict[str, Any]
    start_epoch: int = 0  # first epoch (0-based) trained in this session
    epochs_done: int = 0  # epochs completed by the run so far (all sessions)
    checkpoint: Path | None = None


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
    save_dir = runs_dir / opts.name
    ta.update(data=str(data_yaml.resolve()), project=str(runs_dir), name=opts.name, save_dir=str(save_dir),
              exist_ok=True, device="cpu", workers=opts.workers, cache=opts.cache, time=None, plots=False)
    if opts.epochs and int(opts.epochs) > int(ta.get("epochs", 0)):
        ta["epochs"] = int(opts.epochs)
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
    if opts.resume:
        last = _resume_checkpoint(opts, data_yaml, runs_dir)
        model = YOLO(str(last), task="detect")
        args: dict[str, Any] = dict(resume=str(last))
    else:
        model = YOLO(opts.model, task="detect")
        args = _fresh_args(opts, data_yaml, runs_dir)
    _add_session_callbacks(model, opts, log)
    log(f"{'resuming' if opts.resume else 'training'} {opts.model} on {data_yaml} at {opts.imgsz} px "
        f"(CPU, {torch.get_num_threads()} threads)")
    t0 = time.monotonic()
    model.train(**args)
    train_s = time.monotonic() - t0
    return _finish(model, opts, data_yaml, dataset_meta, train_s, log)


def _fresh_args(opts: TrainOptions, data_yaml: Path, runs_dir: Path) -> dict[str, Any]:
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
        if opts.session_epochs is not None and state["epochs"] >= opts.session_epochs:
            trainer.stop = True
        elif opts.checkpoint is not None and opts.hours and time.monotonic() - t_start + per_epoch > opts.hours * 3600:
            trainer.stop = True
        if trainer.stop and trainer.epoch + 1 < trainer.epochs:
            log(f"session ends after epoch {trainer.epoch + 1} of {trainer.epochs}; continue with --resume")

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
    return TrainResult(out_model, out_card, card, start_epoch=int(getattr(trainer, "start_epoch", 0)),
                       epochs_done=len(rows), checkpoint=Path(opts.checkpoint) if opts.checkpoint else None)


# ------------------------------------------------------------------------------------------------
# Inference variants: static input shape, int8 static quantization (need onnx; onnxruntime for int8)
# ------------------------------------------------------------------------------------------------

#: Node-name prefix of ultralytics' detection head (``Detect``, layer 22 of yolov8n/yolo11n).
HEAD_PREFIX = "/model.22/"


def static_model(src: Path, dst: Path, width: int, height: int, fp16_weights: bool = False) -> dict[str, Any]:
    """Fix an exported model's input to ``[1, 3, height, width]`` and re-simplify it with onnxslim.

    Weights stored as float16 behind casts (:func:`compress_weights_fp16`) are restored to float32
    first, so every shape computation and constant folds away; ``fp16_weights`` stores them as
    float16 again afterwards. Returns a summary (nodes, output shape).
    """
    import numpy as np
    import onnx
    import onnxslim
    from onnx import TensorProto, numpy_helper

    m = onnx.load(str(src))
    g = m.graph
    inits = {i.name: i for i in g.initializer}
    for c in [n for n in g.node if n.op_type == "Cast" and n.input[0] in inits]:
        if inits[c.input[0]].data_type != TensorProto.FLOAT16:
            continue
        a = numpy_helper.to_array(inits[c.input[0]]).astype(np.float32)
        g.initializer.remove(inits[c.input[0]])
        g.initializer.append(numpy_helper.from_array(a, c.output[0]))
        g.node.remove(c)
    if len(g.input) != 1 or len(g.input[0].type.tensor_type.shape.dim) != 4:
        raise ValueError(f"{src}: expected one NCHW input")
    for d, v in zip(g.input[0].type.tensor_type.shape.dim, (1, 3, int(height), int(width))):
        d.Clear()
        d.dim_value = v
    for o in g.output:
        o.type.tensor_type.shape.Clear()  # re-inferred for the static input
    m = onnxslim.slim(m)
    dfl = fast_dfl(m)
    onnx.checker.check_model(m, full_check=True)
    onnx.save(m, str(dst))
    if fp16_weights:
        compress_weights_fp16(Path(dst), Path(dst))
    out = onnx.load(str(dst)).graph.output[0]
    return {"nodes": len(m.graph.node), "output": [d.dim_value for d in out.type.tensor_type.shape.dim], "fast_dfl": dfl}


def fast_dfl(model: Any) -> bool:
    """Rewrite the head's distribution focal loss decoding (``Reshape [1, 4, 16, N] → Transpose →
    Softmax(axis 1) → 1×1 Conv with weights 0…15``) as a softmax expectation along axis 2 without the
    transpose: ``Σ k·exp(x_k − max) / Σ exp(x_k − max)`` (ReduceMax, Sub, Exp, Mul, ReduceSum, Div).
    onnxruntime's Softmax on a non-last axis transposes internally and took ~10 % of the int8 model's
    time. Same result to float rounding. Changes ``model`` in place; False if the pattern is absent."""
    import numpy as np
    from onnx import helper, numpy_helper

    g = model.graph
    prod = {o: n for n in g.node for o in n.output}
    cons: dict[str, list] = {}
    for n in g.node:
        for i in n.input:
            cons.setdefault(i, []).append(n)
    inits = {i.name: i for i in g.initializer}
    for sm in [n for n in g.node if n.op_type == "Softmax"]:
        tr = prod.get(sm.input[0])
        users = cons.get(sm.output[0], [])
        if tr is None or tr.op_type != "Transpose" or len(users) != 1 or users[0].op_type != "Conv":
            continue
        perm = next((list(a.ints) for a in tr.attribute if a.name == "perm"), None)
        conv = users[0]
        if perm != [0, 2, 1, 3] or len(conv.input) != 2 or conv.input[1] not in inits:
            continue
        w = numpy_helper.to_array(inits[conv.input[1]]).astype(np.float32).reshape(-1)
        x, p = tr.input[0], sm.name + "_fast"
        k = numpy_helper.from_array(w.reshape(1, 1, -1, 1), p + "/k")
        axes = numpy_helper.from_array(np.array([2], np.int64), p + "/axes")
        g.initializer.extend([k, axes])
        new = [
            helper.make_node("ReduceMax", [x, axes.name], [p + "/max"], name=p + "/ReduceMax", keepdims=1),
            helper.make_node("Sub", [x, p + "/max"], [p + "/centred"], name=p + "/Sub"),
            helper.make_node("Exp", [p + "/centred"], [p + "/exp"], name=p + "/Exp"),
            helper.make_node("ReduceSum", [p + "/exp", axes.name], [p + "/den"], name=p + "/ReduceSumDen", keepdims=1),
            helper.make_node("Mul", [p + "/exp", k.name], [p + "/weighted"], name=p + "/Mul"),
            helper.make_node("ReduceSum", [p + "/weighted", axes.name], [p + "/num"], name=p + "/ReduceSumNum", keepdims=1),
            helper.make_node("Div", [p + "/num", p + "/den"], [conv.output[0]], name=p + "/Div"),
        ]
        pos = list(g.node).index(tr)
        for n in (tr, sm, conv):
            g.node.remove(n)
        for i, n in enumerate(new):
            g.node.insert(pos + i, n)
        g.initializer.remove(inits[conv.input[1]])
        for vi in [v for v in g.value_info if v.name == conv.output[0]]:
            g.value_info.remove(vi)  # was [1, 1, 4, N]; now [1, 4, 1, N] (the Reshape after it is unchanged)
        return True
    return False


def float_head_nodes(model: Any, head_prefix: str = HEAD_PREFIX, quantize_hidden_convs: bool = True) -> list[str]:
    """Names of the nodes kept in float by :func:`quantize_int8`: the detection head's box and class
    outputs and everything after them (DFL softmax, box decoding, the final concatenations). With
    ``quantize_hidden_convs`` the head's inner 3×3 convolutions (``cv2.k.0/1``, ``cv3.k.0/1``) are
    quantized; only each branch's last convolution stays float."""
    import re

    hidden = re.compile(re.escape(head_prefix) + r"cv[23]\.\d+/cv[23]\.\d+\.[01]/")
    names = []
    for n in model.graph.node:
        if not n.name.startswith(head_prefix):
            continue
        if quantize_hidden_convs and hidden.match(n.name):
            continue
        names.append(n.name)
    return names


class _CalibrationReader:
    """onnxruntime ``CalibrationDataReader`` over RGB images, letterboxed as :class:`Detector` does."""

    def __init__(self, images: list, input_name: str, width: int, height: int) -> None:
        from app.ocslam.detector import letterbox

        self._blobs = iter([{input_name: letterbox(im, width, height)[0]} for im in images])

    def get_next(self):
        return next(self._blobs, None)

    def rewind(self) -> None:  # pragma: no cover - onnxruntime calls it only for some methods
        pass


def load_rgb_images(folder: Path, limit: int | None = None, seed: int = 0) -> list:
    """RGB uint8 images of a dataset folder (``images/**/*.png`` or a folder of PNGs), a seeded sample
    of at most ``limit``."""
    import cv2
    import numpy as np

    folder = Path(folder)
    files = sorted(folder.glob("images/*/*.png")) or sorted(folder.glob("*.png"))
    if not files:
        raise FileNotFoundError(f"no PNG images under {folder} (expected an `ocslam dataset` folder)")
    if limit is not None and len(files) > limit:
        idx = np.random.default_rng(seed).choice(len(files), size=limit, replace=False)
        files = [files[i] for i in sorted(idx)]
    out = []
    for f in files:
        bgr = cv2.imread(str(f), cv2.IMREAD_COLOR)
        if bgr is not None:
            out.append(np.ascontiguousarray(bgr[:, :, ::-1]))
    return out


def quantize_int8(
    src: Path,
    dst: Path,
    calib_images: list,
    quantize_hidden_convs: bool = True,
    per_channel: bool = True,
    method: str = "minmax",
    op_types: tuple[str, ...] | None = None,
    float_prefixes: tuple[str, ...] = (),
) -> dict[str, Any]:
    """onnxruntime static int8 quantization (QDQ, signed int8 activations and weights) of a
    static-shape float model, calibrated on ``calib_images`` (RGB renders), with the detection head's
    outputs and the final concatenations kept in float (:func:`float_head_nodes`). Returns the recipe
    (for the model card)."""
    import onnx
    from onnxruntime.quantization import CalibrationMethod, QuantFormat, QuantType, quantize_static

    m = onnx.load(str(src))
    inp = m.graph.input[0]
    dims = [d.dim_value for d in inp.type.tensor_type.shape.dim]
    if len(dims) != 4 or min(dims) <= 0:
        raise ValueError(f"{src}: quantization needs a static input shape, got {dims}")
    height, width = dims[2], dims[3]
    exclude = float_head_nodes(m, quantize_hidden_convs=quantize_hidden_convs)
    exclude += [n.name for n in m.graph.node if any(n.name.startswith(p) for p in float_prefixes) and n.name not in exclude]
    methods = {"minmax": CalibrationMethod.MinMax, "percentile": CalibrationMethod.Percentile,
               "entropy": CalibrationMethod.Entropy}
    extra: dict[str, Any] = {"ActivationSymmetric": False, "WeightSymmetric": True}
    if method == "percentile":
        extra["CalibPercentile"] = 99.999
    quantize_static(
        str(src),
        str(dst),
        _CalibrationReader(calib_images, inp.name, width, height),
        quant_format=QuantFormat.QDQ,
        op_types_to_quantize=list(op_types) if op_types else None,
        per_channel=per_channel,
        activation_type=QuantType.QUInt8,
        weight_type=QuantType.QInt8,
        nodes_to_exclude=exclude,
        calibrate_method=methods[method],
        extra_options=extra,
    )
    import onnxruntime

    return {
        "tool": f"onnxruntime {onnxruntime.__version__} quantize_static",
        "format": "QDQ",
        "activations": "uint8 (asymmetric, per tensor; u8s8 is the x86 VNNI path)",
        "weights": "int8 (symmetric, " + ("per channel)" if per_channel else "per tensor)"),
        "calibration": f"{method}, {len(calib_images)} images",
        "op_types": list(op_types) if op_types else "onnxruntime's default",
        "float_nodes": (
            "the detection head's last convolution of each branch and everything after it (DFL, box decoding, "
            "sigmoid, final concatenations)" if quantize_hidden_convs else "the whole detection head (layer 22)"
        ),
        "float_prefixes": list(float_prefixes),
        "float_node_count": len(exclude),
    }


def optimize_for_inference(
    src: Path,
    out: Path,
    calib: Path,
    width: int = 224,
    height: int = 192,
    calib_images: int = 120,
    seed: int = 0,
    float_prefixes: tuple[str, ...] = ("/model.0/",),
    card_path: Path | None = None,
    log=print,
) -> dict[str, Any]:
    """Make the app's inference model from a trained float one: static ``[1, 3, height, width]`` input,
    simplified, the DFL without its transpose (:func:`fast_dfl`), then int8 QDQ quantization calibrated
    on ``calib_images`` renders of the ``ocslam dataset`` at ``calib`` (training worlds, never the
    held-out ones) with the detection head's outputs in float. Writes ``out`` and its card (``card_path``,
    default ``out`` with ``.yaml``), which also describes ``src`` as the float reference (``variants``,
    ``lineage.previous``) and keeps the source card's dataset, training and validation sections.
    Returns the card."""
    import tempfile

    from app.ocslam.detector import find_model_card

    src, out, calib = Path(src), Path(out), Path(calib)
    src_card: dict[str, Any] = {}
    found = find_model_card(src)
    if found is not None:
        src_card = yaml.safe_load(found[0].read_text()) or {}
    calib_meta: dict[str, Any] = {}
    if (calib / "data.yaml").is_file():
        calib_meta = (yaml.safe_load((calib / "data.yaml").read_text()) or {}).get("ocslam", {}) or {}
    images = load_rgb_images(calib, limit=calib_images, seed=seed)
    with tempfile.TemporaryDirectory(prefix="ocslam-optimize-") as tmp:
        static = Path(tmp) / "static.onnx"
        log(f"static {width}×{height} float model from {src}")
        summary = static_model(src, static, width, height)
        q = Path(tmp) / "int8.onnx"
        log(f"int8 QDQ quantization, calibrated on {len(images)} images of {calib}")
        recipe = quantize_int8(static, q, images, float_prefixes=float_prefixes)
        atomic_write_bytes(out, q.read_bytes())
    recipe["calibration_data"] = {
        "path": str(calib),
        "command": calib_meta.get("command"),
        "seed": calib_meta.get("seed"),
        "images_used": len(images),
        "sample_seed": seed,
    }
    recipe["command"] = (
        " ".join(["ocslam", "train-detector", *sys.argv[2:]]) if sys.argv[1:2] == ["train-detector"] else None
    )
    src_entry = dict(src_card.get("model") or {})
    card: dict[str, Any] = {
        "model": {
            "file": out.name,
            "architecture": src_entry.get("architecture", "yolov8n"),
            "format": f"onnx, static input [1, 3, {height}, {width}], int8 QDQ (uint8 activations, int8 weights) with "
            "the detection head's outputs in float; output [1, 4 + classes, N] (cx, cy, w, h, class scores)",
            "size_bytes": out.stat().st_size,
            "sha256": _sha256(out),
            "pretrained": False,
        },
        "classes": list(CLASS_NAMES),
        "input": {
            "width": width,
            "height": height,
            "static": True,
            "camera_640x480": [width, height],
            "note": "the app's 320×240 render (and the camera's 640×480) is scaled to 224×168 and letterboxed to 224×192",
        },
        "quantization": recipe,
        "graph": {
            "static_shape": f"[1, 3, {height}, {width}], simplified with onnxslim ({summary['nodes']} nodes)",
            "dfl": "softmax expectation along the bin axis, no transpose (same outputs to float rounding)"
            if summary.get("fast_dfl") else "as exported",
        },
        "lineage": {
            "previous": {"file": src.name, "sha256": _sha256(src), "size_bytes": src.stat().st_size,
                         "format": src_entry.get("format")},
            "steps": [
                f"{src.name}: trained as described under training (float, dynamic input)",
                f"{out.name}: {src.name} with a static {width}×{height} input, fast DFL, int8 static quantization",
            ],
        },
        "variants": [
            {"file": src.name, "sha256": _sha256(src), "role": "float reference (the trained weights, dynamic input, "
             "weights stored as float16, computed in float32); the model the int8 one was quantized from"}
        ],
        "dataset": src_card.get("dataset"),
        "training": src_card.get("training"),
        "validation": src_card.get("validation"),
        "date": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
    }
    card_path = Path(card_path) if card_path else out.with_suffix(".yaml")
    atomic_write_text(card_path, "# Model card of the OCSLAM detector (written by `ocslam train-detector`)\n"
                      + yaml.safe_dump(card, sort_keys=False, width=110, allow_unicode=True))
    log(f"wrote {out} ({out.stat().st_size / 1e6:.1f} MB) and {card_path}")
    return card
