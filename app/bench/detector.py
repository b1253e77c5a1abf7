"""Detector benchmark: precision/recall at the app's threshold, mAP (pycocotools) and latency, on held-out renders.

    ocslam bench detector                          # renders 12 held-out random worlds (seed 99) at 640×480
    ocslam bench detector --data datasets/sim      # the val split (unseen worlds) of an `ocslam dataset`
    ocslam bench detector --worlds 20 --seed 7 --json

Ground truth comes from the simulator's segmentation (app/labels.py). Objects that are visible but
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
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np

from app.bench.common import print_json, table
from app.ocslam.messages import CLASS_NAMES

#: The paper's row (spec §6, Fig. 12): YOLOv8-nano, 224 px, batch 64, 237 epochs, RTX 3050.
PAPER = {"precision": 0.899, "images_per_s": 625.0, "hardware": "RTX 3050 GPU"}
#: Targets of issue 4.
TARGETS = {"map50": 0.95, "precision": 0.95, "recall": 0.95, "per_class": 0.90, "latency_224_2_ms": 5.0}


@dataclass(frozen=True)
class GtBox:
    class_id: int
    x1: float
    y1: float
    x2: float
    y2: float
    ignore: bool = False


@dataclass(frozen=True)
class Sample:
    """One evaluation image: a file (or an in-memory RGB array) and its ground-truth boxes."""

    path: Path | None
    width: int
    height: int
    boxes: tuple[GtBox, ...]
    rgb: np.ndarray | None = None

    def load(self) -> np.ndarray:
        if self.rgb is not None:
            return self.rgb
        import cv2

        bgr = cv2.imread(str(self.path), cv2.IMREAD_COLOR)
        if bgr is None:
            raise FileNotFoundError(f"cannot read image {self.path}")
        return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


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
    per image, for each input width and thread count."""
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


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", type=Path, default=None, help="evaluate an `ocslam dataset` folder instead of rendering")
    p.add_argument("--split", default="val", choices=("val", "train", "all"), help="with --data: which split")
    p.add_argument("--worlds", type=int, default=12, help="held-out random worlds to render (without --data)")
    p.add_argument("--per-world", type=int, default=25, help="images per held-out world")
    p.add_argument("--seed", type=int, default=99, help="held-out world seed base (training used others)")
    p.add_argument("--imgsz", default="640x480", help="held-out render size W×H (the live camera's)")
    p.add_argument("--workers", type=int, default=2, help="rendering processes")
    p.add_argument("--model", type=Path, default=None, help="ONNX model (default: detector.model_path)")
    p.add_argument("--confidence", type=float, default=None, help="threshold (default: detector.confidence)")
    p.add_argument("--latency-images", type=int, default=100, help="images timed per setting")
    p.add_argument("--no-latency", action="store_true")
    p.add_argument("--config", type=Path, default=None, help="config YAML")


def _load_samples(args: argparse.Namespace, quiet: bool) -> tuple[list[Sample], str]:
    from app import dataset

    if args.data is not None:
        return dataset.load_samples(args.data, args.split), f"{args.data} ({args.split})"
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
    return dataset.load_samples(tmp, "val"), desc


def run(args: argparse.Namespace) -> int:
    from app.config import Config
    from app.ocslam.detector import Detector

    cfg_all = Config.load(args.config) if args.config else Config()
    cfg = cfg_all.detector
    conf = float(args.confidence) if args.confidence is not None else float(cfg.confidence)
    det = Detector(cfg, args.model)
    samples, desc = _load_samples(args, quiet=args.json)
    if not samples:
        print("ocslam bench detector: no images to evaluate", file=sys.stderr)
        return 2
    t0 = time.monotonic()
    raw = run_detector(det, samples)
    res = coco_evaluate(samples, raw, conf)
    res["eval_s"] = time.monotonic() - t0
    res["data"] = desc
    res["model"] = str(det.model_path)
    if not args.no_latency:
        imgs = [s.load() for s in samples[: args.latency_images]]
        res["latency_ms_detail"] = measure_latency(cfg, args.model, imgs, (224, 320), (1, 2))
        res["latency_ms"] = {s: {t: v["median"] for t, v in d.items()} for s, d in res["latency_ms_detail"].items()}
        res["latency_image_size"] = f"{imgs[0].shape[1]}x{imgs[0].shape[0]}"
    res["paper"] = PAPER
    res["targets"] = TARGETS
    if args.json:
        print_json(res)
        return 0
    print(f"detector: {det.model_path}\nheld-out data: {desc}; {res['images']} images, {res['instances']} labelled objects; "
          f"threshold {conf}\n")
    rows = [
        [n, v["instances"], v["precision"], v["recall"], v["ap50"]] for n, v in res["per_class"].items()
    ]
    table(["class", "objects", "precision", "recall", "AP50"], rows, title="Per class (IoU 0.5)")
    print()
    ours_ips = None
    if "latency_ms" in res and "224" in res["latency_ms"]:
        ours_ips = 1000.0 / res["latency_ms"]["224"]["2"]
    table(
        ["", "precision", "recall", "mAP50", "mAP50-95", "img/s", "hardware"],
        [
            ["paper (YOLOv8n, 224 px)", PAPER["precision"], None, None, None, PAPER["images_per_s"], PAPER["hardware"]],
            ["ours (YOLOv8n, 224 px)", res["precision"], res["recall"], res["map50"], res["map50_95"], ours_ips,
             "2 CPU threads, onnxruntime"],
            ["target", TARGETS["precision"], TARGETS["recall"], TARGETS["map50"], None, 1000.0 / TARGETS["latency_224_2_ms"], ""],
        ],
        title="Overall",
    )
    if "latency_ms_detail" in res:
        print()
        lrows = []
        for size, d in res["latency_ms_detail"].items():
            for th, v in d.items():
                lrows.append([size, v["input"], th, v["median"], v["p95"]])
        table(["width", "input", "threads", "median ms", "p95 ms"], lrows,
              title=f"Latency per {res['latency_image_size']} image (preprocess + inference + decode + NMS)")
    return 0
