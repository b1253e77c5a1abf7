"""Detector benchmark: precision/recall at the app's threshold, mAP (pycocotools) and latency, on held-out renders.

    ocslam bench detector                          # renders 12 held-out random worlds (seed 99) at 640×480
    ocslam bench detector --data datasets/sim      # the val split (unseen worlds) of an `ocslam dataset`
    ocslam bench detector --worlds 20 --seed 7 --json
    ocslam bench detector --model assets/models/detector-v3.onnx --model assets/models/detector.onnx   # both, and their latency ratio
    ocslam bench detector --compare                # the same: the card's previous model against detector.model_path

Ground truth comes from the simulator's segmentation (app/training/labels.py). Objects that are visible but
fail the label filter (slivers, mostly hidden) are COCO ``iscrowd`` ignore regions: a detection on
them is neither a true nor a false positive. mAP50 and mAP50-95 are pycocotools' (all areas, 100
detections per image); precision and recall use pycocotools' IoU-0.5 matching of the detections at or
above ``detector.confidence``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
import tempfile
import time
from collections.abc import Iterable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from app.bench.common import print_json, table
from app.ocslam.messages import CLASS_NAMES
from app.training.samples import Sample, load_samples

#: The paper's row (spec §6, Fig. 12): YOLOv8-nano, 224 px, batch 64, 237 epochs, RTX 3050.
PAPER = {"precision": 0.899, "images_per_s": 625.0, "hardware": "RTX 3050 GPU"}
#: Targets of issue 10 (latency: at the app's input, 2 threads, pre- and post-processing included).
TARGETS = {"map50": 0.95, "precision": 0.95, "recall": 0.92, "per_class": 0.90, "latency_app_2_ms": 3.0,
           "speedup_vs_previous": 3.0}


def coco_ground_truth(samples: Sequence[Sample]) -> dict[str, Any]:
    """COCO ground-truth dict (category id = class index + 1; ignore boxes are ``iscrowd``)."""
    images, anns = [], []
    for i, s in enumerate(samples):
        images.append({"id": i + 1, "width": s.width, "height": s.height})
        for b in s.boxes:
            w, h = b.x2 - b.x1, b.y2 - b.y1
            anns.append(
                {
                    "id": len(anns) + 1,
                    "image_id": i + 1,
                    "category_id": b.class_id + 1,
                    "bbox": [b.x1, b.y1, w, h],
                    "area": w * h,
                    "iscrowd": int(b.ignore),
                }
            )
    cats = [{"id": i + 1, "name": n} for i, n in enumerate(CLASS_NAMES)]
    return {"images": images, "annotations": anns, "categories": cats}


def coco_evaluate(
    samples: Sequence[Sample],
    detections: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]],
    confidence: float,
) -> dict[str, Any]:
    """pycocotools evaluation. ``detections[i]`` = ``(boxes (K, 4) xyxy, scores (K,), classes (K,))``
    of ``samples[i]``, found at a low threshold (mAP needs the whole precision/recall curve)."""
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    gt = COCO()
    gt.dataset = coco_ground_truth(samples)
    with contextlib.redirect_stdout(io.StringIO()):
        gt.createIndex()
    dts = []
    for i, (boxes, scores, cls) in enumerate(detections):
        for b, s, c in zip(boxes, scores, cls):
            dts.append(
                {
                    "image_id": i + 1,
                    "category_id": int(c) + 1,
                    "bbox": [float(b[0]), float(b[1]), float(b[2] - b[0]), float(b[3] - b[1])],
                    "score": float(s),
                }
            )
    n_cls = len(CLASS_NAMES)
    result: dict[str, Any] = {"images": len(samples)}
    if not dts:
        result.update(map50=0.0, map50_95=0.0, precision=0.0, recall=0.0)
        result["per_class"] = {n: {"precision": 0.0, "recall": 0.0, "ap50": 0.0, "instances": 0} for n in CLASS_NAMES}
        return result
    with contextlib.redirect_stdout(io.StringIO()):
        dt = gt.loadRes(dts)
        ev = COCOeval(gt, dt, "bbox")
        ev.evaluate()
        ev.accumulate()
        ev.summarize()
    result["map50_95"] = float(ev.stats[0])
    result["map50"] = float(ev.stats[1])
    prec = ev.eval["precision"]  # [T, R, K, A, M]
    cat_ids = ev.params.catIds
    # Precision/recall at the threshold, IoU 0.5, area "all", maxDet 100, from pycocotools' matches.
    tp = np.zeros(n_cls)
    fp = np.zeros(n_cls)
    n_gt = np.zeros(n_cls)
    n_area = len(ev.params.areaRng)
    n_img = len(ev.params.imgIds)
    for k, cat in enumerate(cat_ids):
        for i in range(n_img):
            e = ev.evalImgs[k * n_area * n_img + 0 * n_img + i]
            if e is None:
                continue
            c = cat - 1
            n_gt[c] += int(np.sum(np.asarray(e["gtIgnore"]) == 0))
            if not e["dtIds"]:
                continue
            sc = np.asarray(e["dtScores"])
            m = np.asarray(e["dtMatches"])[0] > 0
            ig = np.asarray(e["dtIgnore"])[0].astype(bool)
            on = (sc >= confidence) & ~ig
            tp[c] += np.sum(on & m)
            fp[c] += np.sum(on & ~m)
    per_class = {}
    for k, cat in enumerate(cat_ids):
        c = cat - 1
        p = prec[0, :, k, 0, 2]
        ap50 = float(np.mean(p[p > -1])) if np.any(p > -1) else float("nan")
        per_class[CLASS_NAMES[c]] = {
            "precision": float(tp[c] / (tp[c] + fp[c])) if tp[c] + fp[c] > 0 else float("nan"),
            "recall": float(tp[c] / n_gt[c]) if n_gt[c] > 0 else float("nan"),
            "ap50": ap50,
            "instances": int(n_gt[c]),
        }
    for name in CLASS_NAMES:
        per_class.setdefault(name, {"precision": float("nan"), "recall": float("nan"), "ap50": float("nan"), "instances": 0})
    result["precision"] = float(tp.sum() / (tp.sum() + fp.sum())) if tp.sum() + fp.sum() > 0 else 0.0
    result["recall"] = float(tp.sum() / n_gt.sum()) if n_gt.sum() > 0 else 0.0
    result["per_class"] = per_class
    result["instances"] = int(n_gt.sum())
    result["confidence"] = confidence
    return result


def run_detector(detector, samples: Sequence[Sample], low_conf: float = 0.001):
    """Raw detections of every sample at ``low_conf`` (the model's boxes, for the mAP curve)."""
    from app.ocslam.detector import decode_output

    out = []
    for s in samples:
        rgb = s.load()
        raw, lb = detector.infer(rgb)
        out.append(
            decode_output(raw, detector.num_classes, low_conf, float(detector.cfg.nms_iou), lb, rgb.shape[1], rgb.shape[0])
        )
    return out


def measure_latency(
    cfg, model_path: Path | None, images: Sequence[np.ndarray], sizes: Iterable[int], threads: Iterable[int], repeats: int = 1
) -> dict[str, dict[str, dict[str, float]]]:
    """Median and p95 wall time (ms) of ``Detector.detect`` (preprocessing, inference, decoding, NMS)
    per image, for each input width and thread count (a dynamic model; a static one has one size)."""
    from app.ocslam.detector import Detector
    from app.ocslam.messages import Image

    res: dict[str, dict[str, dict[str, float]]] = {}
    for size in sizes:
        res[str(size)] = {}
        for th in threads:
            det = Detector(replace(cfg, input_size=int(size), threads=int(th)), model_path)
            for rgb in images[:5]:
                det.detect(Image(0.0, rgb))
            times = []
            for _ in range(repeats):
                for rgb in images:
                    t0 = time.perf_counter()
                    det.detect(Image(0.0, rgb))
                    times.append((time.perf_counter() - t0) * 1000.0)
            t = np.asarray(times)
            res[str(size)][str(th)] = {
                "median": float(np.median(t)),
                "p95": float(np.percentile(t, 95)),
                "input": "x".join(str(v) for v in det.input_size_for(images[0].shape[1], images[0].shape[0])),
            }
    return res


def interleaved_latency(
    detectors: Sequence[Any], images: Sequence[np.ndarray], repeats: int = 1, warmup: int = 5
) -> list[dict[str, float]]:
    """Per-image ``Detector.detect`` time (pre-processing, inference, decoding, NMS) of several
    detectors measured **interleaved** (image by image, A then B then A ...), so that a machine whose
    load changes during the run slows every model alike and their ratio stays fair.

    Returns, per detector: wall-time median, p95 and p10 (ms) and the process CPU time median (ms; with
    spin-waiting off it is the work done, whatever else the cores run)."""
    from app.ocslam.messages import Image

    for det in detectors:
        for rgb in images[:warmup]:
            det.detect(Image(0.0, rgb))
    wall: list[list[float]] = [[] for _ in detectors]
    cpu: list[list[float]] = [[] for _ in detectors]
    for _ in range(repeats):
        for rgb in images:
            msg = Image(0.0, rgb)
            for k, det in enumerate(detectors):
                c0, t0 = time.process_time(), time.perf_counter()
                det.detect(msg)
                wall[k].append((time.perf_counter() - t0) * 1000.0)
                cpu[k].append((time.process_time() - c0) * 1000.0)
    out = []
    for w, c in zip(wall, cpu):
        t = np.asarray(w)
        out.append(
            {
                "median": float(np.median(t)),
                "p95": float(np.percentile(t, 95)),
                "p10": float(np.percentile(t, 10)),
                "cpu_median": float(np.median(c)),
                "n": int(t.size),
            }
        )
    return out


def app_images(images: Sequence[np.ndarray], width: int) -> list[np.ndarray]:
    """The images at the app's render width (``camera.render_width``, aspect kept, area interpolation)."""
    import cv2

    out = []
    for im in images:
        h, w = im.shape[:2]
        if width <= 0 or w == width:
            out.append(im)
            continue
        out.append(cv2.resize(im, (int(width), int(round(h * width / w))), interpolation=cv2.INTER_AREA))
    return out


def session_option_sweep(cfg, model_path: Path, images: Sequence[np.ndarray]) -> list[dict[str, Any]]:
    """Latency of one model under each onnxruntime setting: threads 1/2 × spin-waiting × denormals
    flushed to zero (all interleaved, see :func:`interleaved_latency`)."""
    from app.ocslam.detector import Detector

    settings = [(th, spin, dz) for th in (1, 2) for spin in (False, True) for dz in (False, True)]
    dets = [Detector(replace(cfg, threads=th, spin=spin, denormal_as_zero=dz), model_path) for th, spin, dz in settings]
    lat = interleaved_latency(dets, images)
    return [{"threads": th, "spin": spin, "denormal_as_zero": dz, **v} for (th, spin, dz), v in zip(settings, lat)]


def previous_model(model_path: Path) -> Path | None:
    """The model its card names as the previous one (``lineage.previous.file``), for ``--compare``."""
    from app.ocslam.detector import find_model_card

    found = find_model_card(Path(model_path))
    if found is None:
        return None
    import yaml

    card = yaml.safe_load(found[0].read_text()) or {}
    prev = ((card.get("lineage") or {}).get("previous") or {}).get("file")
    return (Path(model_path).parent / prev) if prev else None


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", type=Path, default=None, help="evaluate an `ocslam dataset` folder instead of rendering")
    p.add_argument("--split", default="val", choices=("val", "train", "all"), help="with --data: which split")
    p.add_argument("--worlds", type=int, default=12, help="held-out random worlds to render (without --data)")
    p.add_argument("--per-world", type=int, default=25, help="images per held-out world")
    p.add_argument("--seed", type=int, default=99, help="held-out world seed base (training used others)")
    p.add_argument("--imgsz", default="640x480", help="held-out render size W×H (the live camera's)")
    p.add_argument("--workers", type=int, default=2, help="rendering processes")
    p.add_argument("--model", type=Path, action="append", default=None,
                   help="ONNX model (default: detector.model_path); repeat to compare models (latency ratio to the first)")
    p.add_argument("--compare", action="store_true",
                   help="compare detector.model_path with the previous model its card names (lineage.previous)")
    p.add_argument("--confidence", type=float, default=None, help="threshold (default: detector.confidence)")
    p.add_argument("--latency-images", type=int, default=100, help="images timed per setting")
    p.add_argument("--latency-repeats", type=int, default=1, help="passes over the timed images")
    p.add_argument("--no-latency", action="store_true")
    p.add_argument("--no-accuracy", action="store_true", help="latency only (still needs the images)")
    p.add_argument("--session-options", action="store_true",
                   help="also time the last model under each onnxruntime setting (threads, spinning, denormals)")
    p.add_argument("--sizes", action="store_true", help="single dynamic model: also time 224 and 320 px inputs")
    p.add_argument("--config", type=Path, default=None, help="config YAML")


def _load_samples(args: argparse.Namespace, quiet: bool) -> tuple[list[Sample], str]:
    from app.training import dataset

    if args.data is not None:
        return load_samples(args.data, args.split), f"{args.data} ({args.split})"
    tmp = Path(tempfile.mkdtemp(prefix="ocslam-bench-detector-"))
    w, h = dataset.parse_imgsz(args.imgsz)
    dataset.build_dataset(
        dataset.DatasetOptions(
            out=tmp,
            worlds=args.worlds,
            per_world=args.per_world,
            seed=args.seed,
            imgsz=(w, h),
            workers=args.workers,
            val_fraction=1.0,
            apartment=False,
        ),
        progress=not quiet,
    )
    desc = f"{args.worlds} held-out random worlds × {args.per_world} images, seed {args.seed}, {w}×{h}"
    return load_samples(tmp, "val"), desc


def _describe(det) -> str:
    w, h = det.input_size
    kind = "static" if det._static is not None else "dynamic"
    return f"{Path(det.model_path).name} ({kind} {w}×{h})"


def run(args: argparse.Namespace) -> int:
    from app.config import Config, resolve_path
    from app.ocslam.detector import Detector, DetectorError

    cfg_all = Config.load(args.config) if args.config else Config()
    cfg = cfg_all.detector
    conf = float(args.confidence) if args.confidence is not None else float(cfg.confidence)
    models: list[Path] = list(args.model or [])
    if args.compare:
        current = models[-1] if models else resolve_path(cfg.model_path)
        prev = previous_model(current)
        if prev is None:
            print(f"ocslam: error: --compare: the card of {current} names no previous model (lineage.previous)", file=sys.stderr)
            return 2
        models = [prev, current]
    if not models:
        models = [resolve_path(cfg.model_path)]
    try:
        dets = [Detector(cfg, m) for m in models]
    except DetectorError as e:
        print(f"ocslam: error: {e}", file=sys.stderr)
        return 2
    samples, desc = _load_samples(args, quiet=args.json)
    if not samples:
        print("ocslam bench detector: no images to evaluate", file=sys.stderr)
        return 2
    results: list[dict[str, Any]] = []
    for det in dets:
        res: dict[str, Any] = {"model": str(det.model_path), "input": list(det.input_size), "sha256": det.sha256}
        if not args.no_accuracy:
            t0 = time.monotonic()
            raw = run_detector(det, samples)
            res.update(coco_evaluate(samples, raw, conf))
            res["eval_s"] = time.monotonic() - t0
        results.append(res)
    out: dict[str, Any] = {"data": desc, "images": len(samples), "confidence": conf}
    if not args.no_latency:
        app_w = int(cfg_all.camera.render_width) or int(cfg_all.camera.width)
        imgs = app_images([s.load() for s in samples[: args.latency_images]], app_w)
        out["latency_image_size"] = f"{imgs[0].shape[1]}x{imgs[0].shape[0]}"
        out["latency_threads"] = {}
        for th in (2, 1):
            tdets = [Detector(replace(cfg, threads=th), m) for m in models]
            lat = interleaved_latency(tdets, imgs, repeats=args.latency_repeats)
            out["latency_threads"][str(th)] = lat
            for res, v in zip(results, lat):
                res.setdefault("latency_app_ms", {})[str(th)] = v
        if len(dets) > 1:
            base = out["latency_threads"]["2"][0]
            out["speedup_vs_first"] = {
                str(th): [out["latency_threads"][str(th)][0]["median"] / v["median"] for v in out["latency_threads"][str(th)]]
                for th in (2, 1)
            }
            out["speedup_vs_first_cpu"] = [base["cpu_median"] / v["cpu_median"] for v in out["latency_threads"]["2"]]
        if args.session_options:
            out["session_options"] = session_option_sweep(cfg, models[-1], imgs)
        if len(dets) == 1 and dets[0]._static is None and args.sizes:
            full = [s.load() for s in samples[: args.latency_images]]
            out["latency_ms_detail"] = measure_latency(cfg, models[0], full, (224, 320), (1, 2))
    out["models"] = results
    out["paper"] = PAPER
    out["targets"] = TARGETS
    if len(results) == 1:  # the single-model layout of earlier versions (flat keys)
        out.update({k: v for k, v in results[0].items() if k not in out})
    if args.json:
        print_json(out, file=sys.stdout)
        return 0
    print(f"held-out data: {desc}; {len(samples)} images; threshold {conf}")
    for det, res in zip(dets, results):
        print(f"\nmodel: {det.model_path}  [{_describe(det)}]")
        if "per_class" not in res:
            continue
        print(f"{res['instances']} labelled objects")
        rows = [[n, v["instances"], v["precision"], v["recall"], v["ap50"]] for n, v in res["per_class"].items()]
        rows.append(["all", res["instances"], res["precision"], res["recall"], res["map50"]])
        table(["class", "objects", "precision", "recall", "AP50"], rows, title="Per class (IoU 0.5)")
    if any("per_class" in r for r in results):
        print()
        rows = [["paper (YOLOv8n, 224 px)", PAPER["precision"], None, None, None, PAPER["hardware"]]]
        for det, res in zip(dets, results):
            if "per_class" in res:
                rows.append([_describe(det), res["precision"], res["recall"], res["map50"], res["map50_95"], "CPU, onnxruntime"])
        rows.append(["target", TARGETS["precision"], TARGETS["recall"], TARGETS["map50"], None, ""])
        table(["", "precision", "recall", "mAP50", "mAP50-95", "hardware"], rows, title="Overall")
    if "latency_threads" in out:
        print()
        rows = []
        for th in ("2", "1"):
            for det, v in zip(dets, out["latency_threads"][th]):
                ratio = out["latency_threads"][th][0]["median"] / v["median"]
                rows.append([_describe(det), th, v["median"], v["p95"], v["p10"], v["cpu_median"], ratio if len(dets) > 1 else None])
        table(["model", "threads", "median ms", "p95 ms", "p10 ms", "CPU ms", "× first"], rows,
              title=f"Latency per {out['latency_image_size']} image (the app's render; preprocess + inference + decode + NMS), interleaved")
    if "session_options" in out:
        print()
        rows = [[v["threads"], v["spin"], v["denormal_as_zero"], v["median"], v["p95"], v["cpu_median"]] for v in out["session_options"]]
        table(["threads", "spin", "denormal→0", "median ms", "p95 ms", "CPU ms"], rows,
              title=f"onnxruntime session options, {Path(models[-1]).name}")
    if "latency_ms_detail" in out:
        print()
        lrows = [[size, v["input"], th, v["median"], v["p95"]] for size, d in out["latency_ms_detail"].items() for th, v in d.items()]
        table(["width", "input", "threads", "median ms", "p95 ms"], lrows, title="Latency per full-size image, dynamic input")
    return 0
