"""Train the YOLO detector from scratch on an `ocslam dataset` and write assets/models/detector.onnx + its card.

Needs the optional [train] extra (pip install -e '.[train]'). Runs fully offline on the CPU; about an
hour on 2 cores with the defaults (see docs/detector.md):

    ocslam dataset --worlds 40 --per-world 45 --seed 1 --out datasets/sim
    ocslam train-detector --data datasets/sim --hours 1

Without a dataset at --data (default datasets/sim) it renders one with that recipe first.

One long schedule over many sessions: every epoch's full state (weights, optimizer, learning-rate
schedule, epoch counter) is copied to --checkpoint (default assets/models/detector-train.pt; a new run
writes its own in its run folder when a run is already saved there, and says so), and

    ocslam train-detector --resume [--epochs TOTAL] [--hours H]

continues that same run; --hours stops it cleanly at the end of an epoch (the schedule is the run's,
not refitted to the budget). --data may be repeated (the union of datasets), and a run may be resumed on
other data: its weights, optimizer and schedule go on, its best-epoch tracking starts again:

    ocslam dataset --worlds 120 --per-world 45 --seed 2 --no-apartment --val-fraction 0.1 --out datasets/sim2-families
    ocslam train-detector --resume --data datasets/sim --data datasets/sim2-families --hours 1.6

A new run that refines a trained model takes --lr0 (low), --warmup-epochs 0 and --optimizer.

A committed float ONNX model (whose PyTorch checkpoint was not kept) can be trained further: its weights
are converted into an ultralytics checkpoint under the run folder (app.training.onnx_init; same outputs)
and used as --init-weights:

    ocslam train-detector --data datasets/sim --init-onnx assets/models/detector-v3.onnx --name v4-from-v3

The app's inference model is made from a trained float model (static input, int8; needs onnx,
onnxslim and onnxruntime, no torch):

    ocslam dataset --worlds 6 --per-world 15 --seed 1 --imgsz 320x240 --apartment-images 30 --val-fraction 0 --out datasets/calib
    ocslam train-detector --optimize assets/models/detector-v3.onnx --calib datasets/calib --out assets/models/detector.onnx
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from app.training.narrow import (  # numpy only at import; torch when a network is built
    ACTIVATIONS,
    WIDTH_RANGE,
)

if TYPE_CHECKING:
    from app.training.train import TrainOptions

#: The dataset recipe of the committed model (app.training.dataset.DatasetOptions defaults).
DEFAULT_DATASET_COMMAND = "ocslam dataset --worlds 40 --per-world 45 --seed 1 --families rooms --out {out}"
#: The calibration renders of the committed int8 model (six training worlds and the apartment, the app's 320×240).
CALIB_DATASET_COMMAND = (
    "ocslam dataset --worlds 6 --per-world 15 --seed 1 --families rooms --imgsz 320x240 --apartment-images 30 "
    "--val-fraction 0 --out {out}"
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--data",
        type=Path,
        action="append",
        default=None,
        help="dataset folder (with data.yaml) from `ocslam dataset` (default datasets/sim, rendered with the "
        "committed model's recipe if missing); repeat it to train on the union of several datasets",
    )
    p.add_argument("--model", default="yolov8n.yaml", help="ultralytics model yaml (no pretrained weights): yolov8n.yaml, yolo11n.yaml")
    p.add_argument("--init-weights", type=Path, default=None,
                   help="start from an earlier checkpoint of ours (e.g. runs/detector/v1/weights/best.pt); never a download")
    p.add_argument("--init-onnx", type=Path, default=None, metavar="FLOAT_ONNX",
                   help="start from the weights of a float ONNX model exported by this command (e.g. "
                        "assets/models/detector-v3.onnx): converted to <runs>/<name>/init-<stem>.pt first")
    p.add_argument("--init-prune", type=Path, default=None, metavar="CHECKPOINT",
                   help="start a narrower network (--width) from the most important channels of each layer of this "
                        "trained checkpoint (e.g. assets/models/detector-train.pt; app.training.narrow)")
    p.add_argument("--width", type=float, default=None,
                   help="YOLOv8 width multiple of a new network (YOLOv8n: 0.25; e.g. 0.125 for about half the latency)")
    p.add_argument("--act", choices=tuple(ACTIVATIONS), default=None,
                   help="with --width: the network's activation (YOLOv8: silu; relu is fused into int8 convolutions)")
    p.add_argument("--distill", type=Path, default=None, metavar="CHECKPOINT",
                   help="a new run learns also from this trained (wider) teacher checkpoint's features "
                        "(ultralytics' knowledge distillation)")
    p.add_argument("--init-onnx-calib", type=int, default=128, metavar="N",
                   help="with --init-onnx: BatchNorm statistics from N training images (0: identity BatchNorms)")
    p.add_argument("--imgsz", type=int, default=224, help="training image size (paper: 224)")
    p.add_argument("--epochs", type=int, default=None,
                   help="epochs of the run's schedule (default 60; with --resume: the saved run's, or this to extend it)")
    p.add_argument("--hours", type=float, default=1.0,
                   help="this session's time budget in hours: it ends at the last epoch that fits (0: off); the schedule "
                        "is --epochs, continued by --resume")
    p.add_argument("--batch", type=int, default=None,
                   help="images a batch (default 16; with --resume: the saved run's, or this one, e.g. 64 on a GPU: "
                        "gradients are accumulated to 64 images a step either way)")
    p.add_argument("--lr0", type=float, default=None,
                   help="initial learning rate (default: ultralytics' choice for the optimizer); low to refine a model")
    p.add_argument("--warmup-epochs", type=float, default=None,
                   help="learning-rate warm-up epochs (default ultralytics' 3; 0 to refine a trained model)")
    p.add_argument("--optimizer", choices=("auto", "SGD", "AdamW", "Adam"), default=None,
                   help="optimizer (default auto: ultralytics picks by the run's length)")
    p.add_argument("--patience", type=int, default=None,
                   help="stop after this many epochs without a better val mAP (default 15; with --resume: the saved "
                        "run's, or this to change it)")
    p.add_argument("--workers", type=int, default=2, help="data loader processes")
    p.add_argument("--device", default="cpu",
                   help="torch device: cpu (default) or a CUDA device index such as 0 (the [train] extra's torch "
                        "runs there unchanged; the run's schedule, data and checkpoint are the same)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--close-mosaic", type=int, default=10, help="last epochs trained without mosaic augmentation")
    p.add_argument("--no-cache", action="store_true", help="don't cache the decoded images in RAM")
    p.add_argument("--out", type=Path, default=None,
                   help="trained float ONNX (default: assets/models/detector-float.onnx, card beside it); with --optimize: "
                        "the int8 output (default: beside FLOAT_ONNX, named <its stem>-int8.onnx; the app's model only when named)")
    p.add_argument("--runs", type=Path, default=None, help="ultralytics run folder (default: runs/detector)")
    p.add_argument("--name", default="train", help="run name inside --runs")
    p.add_argument("--resume", action="store_true",
                   help="continue the run saved in --checkpoint (optimizer, LR schedule, epoch counter)")
    p.add_argument("--checkpoint", type=Path, default=None,
                   help="resumable checkpoint written every epoch (default: assets/models/detector-train.pt, which "
                   "--resume continues; a new run writes its own in its run folder when a run is saved there)")
    p.add_argument("--fit-schedule", action="store_true",
                   help="with --resume and --hours: after this session's first epoch, move the schedule's end to the "
                        "last epoch the budget holds, so the learning rate anneals fully within it (a lent machine)")
    p.add_argument("--session-epochs", type=int, default=None,
                   help="end this session after this many epochs (the run's schedule is kept; continue with --resume)")
    p.add_argument("--optimize", type=Path, default=None, metavar="FLOAT_ONNX",
                   help="no training: make the static-shape int8 inference model from this float model (see --calib)")
    p.add_argument("--score-calibration", type=Path, default=None, metavar="DATASET",
                   help="no training: fit --app-model's score → probability map (Platt scaling) on this `ocslam "
                        "dataset`'s val renders (worlds it never saw, rendered as the app renders) and write it "
                        "into the model's card")
    p.add_argument("--calib", type=Path, default=Path("datasets/calib"),
                   help="with --optimize: `ocslam dataset` folder of calibration renders (training worlds)")
    p.add_argument("--calib-images", type=int, default=120, help="with --optimize: calibration images used")
    p.add_argument("--app-model", type=Path, default=Path("assets/models/detector.onnx"),
                   help="after training: the int8 inference model made from the trained one (card beside it)")
    p.add_argument("--no-int8", action="store_true", help="after training: leave the app's model as it is")
    p.add_argument("--static", default="224x192", help="with --optimize: static input W×H (the app's 320×240 → 224×192)")


def run_checkpoint(given: Path | None, resume: bool, default: Path, run_dir: Path) -> Path:
    """Where a run's resumable checkpoint is written every epoch: ``given`` (``--checkpoint``); else the committed
    ``default``, which ``--resume`` continues; a *new* run writes it only if no run is saved there yet, and
    otherwise in its own run folder (``run_dir/train.pt``): starting a run never overwrites another's."""
    if given is not None:
        return Path(given)
    if resume or not Path(default).exists():
        return Path(default)
    return Path(run_dir) / "train.pt"


def run(args: argparse.Namespace) -> int:
    import sys

    from app.training.train import TrainingUnavailable, TrainOptions, train_detector

    if args.optimize is not None:
        return _optimize(args)
    if args.score_calibration is not None:
        return _score_calibration(args)
    if args.init_onnx is not None:
        clash = "--init-weights" if args.init_weights is not None else "--resume" if args.resume else None
        if clash:
            print(f"ocslam: error: --init-onnx and {clash} exclude each other (both say where the weights come from)",
                  file=sys.stderr)
            return 2
        if not args.init_onnx.is_file():
            print(f"ocslam: error: --init-onnx: no ONNX model at {args.init_onnx}", file=sys.stderr)
            return 2
    if args.device != "cpu" and not all(part.isdigit() for part in args.device.split(",")):
        print(f"ocslam: error: --device must be cpu or CUDA device indices such as 0 or 0,1 (got {args.device!r})",
              file=sys.stderr)
        return 2
    if args.batch is not None and args.batch < 1:
        print("ocslam: error: --batch must be at least 1", file=sys.stderr)
        return 2
    if args.fit_schedule and not args.hours:
        print("ocslam: error: --fit-schedule needs --hours (it fits the run's schedule to a budget)", file=sys.stderr)
        return 2
    rc = _check_narrow_args(args)
    if rc:
        return rc
    datasets = list(args.data or [Path("datasets/sim")])
    bad = [str(d) for d in datasets if len(datasets) > 1 and not ((d / "data.yaml").is_file() or d.is_file())]
    if bad:
        print(f"ocslam: error: --data: no dataset (data.yaml) at {', '.join(bad)}", file=sys.stderr)
        return 2
    args.data = datasets[0]
    for name, bound in (("lr0", (0.0, 1.0)), ("warmup_epochs", (0.0, 100.0))):
        v = getattr(args, name)
        if v is not None and not bound[0] <= v <= bound[1]:
            print(f"ocslam: error: --{name.replace('_', '-')} must be in [{bound[0]:g}, {bound[1]:g}]", file=sys.stderr)
            return 2
    extra = {k: v for k, v in (("lr0", args.lr0), ("warmup_epochs", args.warmup_epochs), ("optimizer", args.optimizer))
             if v is not None}
    if args.lr0 is not None and args.optimizer in (None, "auto"):
        print("ocslam: error: --lr0 needs --optimizer SGD, AdamW or Adam (with auto, ultralytics picks its own rate and "
              "ignores --lr0)", file=sys.stderr)
        return 2
    if args.resume and extra:
        print("ocslam: error: --resume continues the saved run's schedule; --lr0/--warmup-epochs/--optimizer "
              "apply to a new run", file=sys.stderr)
        return 2
    opts = TrainOptions(
        data=args.data,
        extra=extra,
        model=args.model,
        imgsz=args.imgsz,
        epochs=args.epochs if args.epochs is not None else (0 if args.resume else 60),
        hours=args.hours or None,
        batch=args.batch if args.batch is not None and not args.resume else 16,
        resume_batch=args.batch if args.resume else None,
        patience=args.patience,
        workers=args.workers,
        seed=args.seed,
        cache=not args.no_cache,
        close_mosaic=args.close_mosaic,
        name=args.name,
        init_weights=args.init_weights,
        resume=args.resume,
        device=args.device,
        fit_schedule=args.fit_schedule,
    )
    from app.config import PROJECT_ROOT

    if args.runs is not None:
        opts.runs_dir = args.runs
    default_checkpoint = PROJECT_ROOT / "assets" / "models" / "detector-train.pt"
    opts.checkpoint = run_checkpoint(args.checkpoint, args.resume, default_checkpoint, Path(opts.runs_dir) / opts.name)
    if args.checkpoint is None and opts.checkpoint != default_checkpoint:
        print(f"checkpoint: {opts.checkpoint} (assets/models/detector-train.pt holds another run; continue this one with "
              f"--resume --checkpoint {opts.checkpoint})")
    opts.session_epochs = args.session_epochs
    # The trained float model goes beside the app's int8 one, which is made from it afterwards.
    opts.out_model = args.out if args.out is not None else PROJECT_ROOT / "assets" / "models" / "detector-float.onnx"
    if args.data.is_dir() and not (args.data / "data.yaml").exists() and any(args.data.iterdir()):
        print(f"ocslam train-detector: {args.data} exists but has no data.yaml", file=sys.stderr)
        return 2
    if not (args.data / "data.yaml").exists() and not args.data.is_file():
        from app.training.dataset import DatasetOptions, build_dataset

        recipe = DatasetOptions(out=args.data, families=("rooms",))
        recipe.command = DEFAULT_DATASET_COMMAND.format(out=args.data)
        print(f"no dataset at {args.data}: rendering one first ({recipe.command})")
        build_dataset(recipe)
    if len(datasets) > 1:
        from app.training.train import combine_datasets

        try:
            opts.data = combine_datasets(datasets, Path(opts.runs_dir) / opts.name / "data.yaml")
        except (FileNotFoundError, ValueError) as e:
            print(f"ocslam: error: --data: {e}", file=sys.stderr)
            return 2
    if args.init_onnx is not None:
        rc = _init_from_onnx(args, opts)
        if rc:
            return rc
    if args.width is not None:
        rc = _narrow_model(args, opts)
        if rc:
            return rc
    if args.distill is not None:
        opts.extra["distill_model"] = str(args.distill.resolve())
    try:
        res = train_detector(opts)
    except TrainingUnavailable as e:
        print(f"ocslam train-detector: {e}", file=sys.stderr)
        return 2
    except (FileNotFoundError, ValueError) as e:
        print(f"ocslam: error: {e}", file=sys.stderr)
        return 2
    v = res.card["validation"]
    print(
        f"done: {res.model_path} ({res.card['training']['epochs_run']} epochs, "
        f"{res.card['training']['training_time_h']:.2f} h); val precision {v['precision']}, recall {v['recall']}, "
        f"mAP50 {v['map50']}, mAP50-95 {v['map50_95']}"
    )
    if args.no_int8:
        return 0
    calib = args.calib
    if not (calib / "data.yaml").exists():
        from app.training.dataset import DatasetOptions, build_dataset

        recipe = DatasetOptions(out=calib, worlds=6, per_world=15, seed=1, imgsz=(320, 240), val_fraction=0.0,
                                apartment_images=30)
        recipe.command = CALIB_DATASET_COMMAND.format(out=calib)
        print(f"no calibration renders at {calib}: rendering them ({recipe.command})")
        build_dataset(recipe)
    args.optimize = res.model_path
    args.out = args.app_model
    return _optimize(args)


def _calibration_images(data: Path, n: int) -> list[Path]:
    """Up to ``n`` training images of the dataset at ``data`` (folder or data.yaml, ``train`` a folder or
    a list of folders), evenly spread over the sorted file names."""
    import yaml

    y = data / "data.yaml" if data.is_dir() else data
    if n <= 0 or not y.is_file():
        return []
    d = yaml.safe_load(y.read_text()) or {}
    base = Path(d["path"]) if d.get("path") else y.parent
    if not base.is_absolute() and not base.is_dir():  # ultralytics also takes it relative to the yaml's folder
        base = y.parent / base
    train = d.get("train") or []
    folders = [base / t for t in ([train] if isinstance(train, str) else train)]
    files = sorted(p for f in folders if f.is_dir() for p in f.iterdir()
                   if p.suffix.lower() in (".png", ".jpg", ".jpeg", ".bmp"))
    if len(files) <= n:
        return files
    step = len(files) / n
    return [files[int(i * step)] for i in range(n)]


def _check_narrow_args(args: argparse.Namespace) -> int:
    """One line for each misuse of --width / --init-prune / --distill. Returns an exit status (0: fine)."""
    import sys

    err = None
    if args.resume and (args.width is not None or args.init_prune is not None or args.distill is not None):
        err = "--width, --init-prune and --distill start a new run; --resume continues the saved one as it is"
    elif (args.init_prune is not None or args.act is not None) and args.width is None:
        err = "--init-prune and --act need --width (the new network's width multiple; YOLOv8n's is 0.25)"
    elif args.init_prune is not None and (args.init_weights is not None or args.init_onnx is not None):
        err = "--init-prune, --init-weights and --init-onnx exclude each other (each says where the weights come from)"
    elif args.width is not None and not WIDTH_RANGE[0] <= args.width <= WIDTH_RANGE[1]:
        err = f"--width must be in [{WIDTH_RANGE[0]:g}, {WIDTH_RANGE[1]:g}] (YOLOv8n is 0.25), got {args.width:g}"
    else:
        for name in ("init_prune", "distill"):
            path = getattr(args, name)
            if path is not None and not path.is_file():
                err = f"--{name.replace('_', '-')}: no checkpoint at {path}"
    if err:
        print(f"ocslam: error: {err}", file=sys.stderr)
        return 2
    return 0


def _narrow_model(args: argparse.Namespace, opts: TrainOptions) -> int:
    """--width: the run's model yaml (YOLOv8n at that width) under the run folder; with --init-prune, its
    init weights pruned from that checkpoint. Returns an exit status (0: go on)."""
    import sys

    from app.ocslam.messages import CLASS_NAMES
    from app.training.train import MISSING_EXTRA, setup_offline

    run_dir = Path(opts.runs_dir) / opts.name
    act = args.act or "silu"
    model_yaml = run_dir / f"yolov8n-w{args.width:g}{'' if act == 'silu' else '-' + act}.yaml"
    try:
        setup_offline(opts.config_dir)
        from app.training.narrow import narrow_yaml, prune_checkpoint
    except ImportError:
        print(f"ocslam train-detector: {MISSING_EXTRA}", file=sys.stderr)
        return 2
    nc = len(CLASS_NAMES)  # the training refuses a dataset with other classes (train._data_yaml)
    try:
        if args.init_prune is not None:
            out_pt = run_dir / f"init-pruned-{args.init_prune.stem}-w{args.width:g}.pt"
            prune_checkpoint(args.init_prune, args.width, out_pt, model_yaml, act)
            opts.init_weights = out_pt
            print(f"--init-prune: {args.init_prune} → {out_pt} (width {args.width:g}, {act}, the channels with the "
                  "largest BatchNorm scales)")
        else:
            narrow_yaml(args.width, nc, model_yaml, act)
    except ValueError as e:
        print(f"ocslam: error: --width/--init-prune: {e}", file=sys.stderr)
        return 2
    opts.model = str(model_yaml)
    return 0


def _init_from_onnx(args: argparse.Namespace, opts: TrainOptions) -> int:
    """Convert ``--init-onnx`` into an ultralytics checkpoint under the run folder and make it the
    run's init weights. Returns an exit status (0: go on)."""
    import sys

    from app.training.onnx_init import OnnxInitError, onnx_to_checkpoint
    from app.training.train import TrainingUnavailable

    out_pt = Path(opts.runs_dir) / opts.name / f"init-{args.init_onnx.stem}.pt"
    calib = _calibration_images(args.data, args.init_onnx_calib)
    try:
        res = onnx_to_checkpoint(args.init_onnx, out_pt, model_yaml=args.model, imgsz=args.imgsz, calib_images=calib)
    except TrainingUnavailable as e:
        print(f"ocslam train-detector: {e}", file=sys.stderr)
        return 2
    except (FileNotFoundError, OnnxInitError) as e:
        print(f"ocslam: error: --init-onnx: {e}", file=sys.stderr)
        return 2
    bn = f"BatchNorm statistics from {len(calib)} training images" if res.bn_calibrated else "identity BatchNorms"
    print(f"--init-onnx: {args.init_onnx} → {out_pt} ({res.convs_loaded} convolutions, {bn})")
    opts.init_weights = out_pt
    return 0


def _optimize(args: argparse.Namespace) -> int:
    import sys

    from app.training.optimize import optimize_for_inference

    try:
        w, h = (int(v) for v in str(args.static).lower().split("x"))
    except ValueError:
        print(f"ocslam: error: --static must be W×H, e.g. 224x192, got {args.static!r}", file=sys.stderr)
        return 2
    if w % 32 or h % 32:
        print(f"ocslam: error: --static {w}x{h}: both sides must be multiples of 32", file=sys.stderr)
        return 2
    if not args.optimize.is_file():
        print(f"ocslam: error: no model at {args.optimize}", file=sys.stderr)
        return 2
    try:
        import onnx  # noqa: F401
        import onnxslim  # noqa: F401
    except ImportError as e:
        print(f"ocslam: error: --optimize needs onnx and onnxslim (pip install onnx onnxslim, or the [train] extra): {e}",
              file=sys.stderr)
        return 2
    # beside the float model unless named: a candidate's int8 must not replace the app's model unasked
    out = args.out or args.optimize.with_name(args.optimize.stem + "-int8.onnx")
    try:
        optimize_for_inference(args.optimize, out, args.calib, w, h, calib_images=args.calib_images)
    except (FileNotFoundError, ValueError) as e:
        print(f"ocslam: error: {e}", file=sys.stderr)
        return 2
    return 0


def _score_calibration(args: argparse.Namespace) -> int:
    import shlex
    import sys

    from app.config import Config
    from app.ocslam.detector import Detector, DetectorError
    from app.training.score_calibration import fit_score_calibration, write_card_calibration

    data = args.score_calibration
    if not (data / "data.yaml").is_file():
        print(f"ocslam: error: --score-calibration: no dataset (data.yaml) at {data}", file=sys.stderr)
        return 2
    cfg = Config().detector
    cfg.calibration = "off"
    try:
        det = Detector(cfg, args.app_model)
        entry = fit_score_calibration(det, data)
        command = "ocslam train-detector --score-calibration " + shlex.quote(str(data))
        if args.app_model != Path("assets/models/detector.onnx"):
            command += " --app-model " + shlex.quote(str(args.app_model))
        card = write_card_calibration(args.app_model, entry, command)
    except (DetectorError, ValueError, OSError) as e:
        print(f"ocslam: error: {e}", file=sys.stderr)
        return 2
    fo = entry["fitted_on"]
    print(f"score calibration of {args.app_model.name}: p = σ({entry['slope']:.3f}·logit(s) + {entry['offset']:.3f}) "
          f"from {fo['boxes']} boxes ({fo['right']} right) on {fo['images']} renders; ECE {entry['ece_before']:.3f} → "
          f"{entry['ece_after']:.3f}; score for p = 0.8: {entry['score_for_probability']['0.80']:.3f}; wrote {card}")
    return 0
