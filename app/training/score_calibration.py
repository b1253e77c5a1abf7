"""Fit a detector's score calibration on labelled renders and write it into its model card.

    ocslam dataset --worlds 16 --per-world 25 --seed 3 --imgsz 320x240 --val-fraction 1.0 --no-apartment \\
        --renderer auto --no-randomize --out datasets/calib-prob-s3
    ocslam train-detector --score-calibration datasets/calib-prob-s3

The boxes are the ones the object map receives: the model's, at the app's input and threshold
(``detector.confidence``), on renders of worlds the network never saw (a dataset seed it was not
trained on), rendered as the app renders them (the app's renderer and size, no domain randomisation).
A box is right when it overlaps an unmatched true object of its class by IoU ≥ 0.5 (best score first,
as COCO matches); a box on an object the labels leave out (a sliver, mostly hidden) counts neither
way. :func:`app.ocslam.calibration.fit_platt` fits ``p = σ(a·logit(s) + b)`` to them.
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from app.config import project_relative
from app.ocslam.calibration import expected_calibration_error, fit_platt, reliability
from app.ocslam.messages import CLASS_NAMES
from app.training.samples import Sample, load_samples

CARD_HEADER = "# Model card of the OCSLAM detector (written by `ocslam train-detector`)\n"


def _iou(box: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """IoU of one ``(4,)`` xyxy box with ``(M, 4)`` boxes."""
    if len(boxes) == 0:
        return np.zeros(0)
    x1 = np.maximum(box[0], boxes[:, 0])
    y1 = np.maximum(box[1], boxes[:, 1])
    x2 = np.minimum(box[2], boxes[:, 2])
    y2 = np.minimum(box[3], boxes[:, 3])
    inter = np.clip(x2 - x1, 0, None) * np.clip(y2 - y1, 0, None)
    a = (box[2] - box[0]) * (box[3] - box[1])
    b = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
    return inter / np.maximum(a + b - inter, 1e-9)


def match_boxes(sample: Sample, boxes: np.ndarray, scores: np.ndarray, classes: np.ndarray,
                iou: float = 0.5) -> np.ndarray:
    """``(K,)`` outcome of each detection of ``sample``: 1 right, 0 wrong, -1 on an ignored object.

    Best score first, each detection takes the unmatched labelled object of its class it overlaps most
    (IoU ≥ ``iou``); one that matches none but overlaps an ignored object of its class by ``iou`` is -1."""
    out = np.zeros(len(scores), dtype=np.int8)
    gt = [(np.array([b.x1, b.y1, b.x2, b.y2]), int(b.class_id), bool(b.ignore)) for b in sample.boxes]
    taken = np.zeros(len(gt), dtype=bool)
    for k in np.argsort(-np.asarray(scores), kind="stable"):
        same = [i for i, g in enumerate(gt) if g[1] == int(classes[k])]
        real = [i for i in same if not gt[i][2] and not taken[i]]
        if real:
            ious = _iou(boxes[k], np.stack([gt[i][0] for i in real]))
            j = int(np.argmax(ious))
            if ious[j] >= iou:
                taken[real[j]] = True
                out[k] = 1
                continue
        ign = [i for i in same if gt[i][2]]
        if ign and float(np.max(_iou(boxes[k], np.stack([gt[i][0] for i in ign])))) >= iou:
            out[k] = -1
    return out


def labelled_scores(detector: Any, samples: Sequence[Sample], floor: float,
                    progress: Callable[[int, int], None] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The scores ``(N,)``, outcomes ``(N,)`` (bool, right) and classes ``(N,)`` of every box ≥ ``floor``
    that ``detector`` finds on ``samples`` (ignored ones left out)."""
    from app.ocslam.detector import decode_output

    scores, right, classes = [], [], []
    for n, s in enumerate(samples):
        rgb = s.load()
        raw, lb = detector.infer(rgb)
        boxes, sc, cls = decode_output(raw, detector.num_classes, float(floor), float(detector.cfg.nms_iou), lb,
                                       rgb.shape[1], rgb.shape[0])
        m = match_boxes(s, boxes, sc, cls)
        keep = m >= 0
        scores.append(np.asarray(sc, dtype=np.float64)[keep])
        right.append(m[keep] == 1)
        classes.append(np.asarray(cls, dtype=np.int64)[keep])
        if progress is not None:
            progress(n + 1, len(samples))
    if not scores:
        return np.zeros(0), np.zeros(0, dtype=bool), np.zeros(0, dtype=np.int64)
    return np.concatenate(scores), np.concatenate(right), np.concatenate(classes)


def fit_score_calibration(detector: Any, data_dir: Path, split: str = "val", floor: float | None = None,
                          progress: Callable[[int, int], None] | None = None) -> dict[str, Any]:
    """Fit ``detector``'s Platt scaling on ``data_dir``'s ``split`` renders; the card entry, with its
    evidence (boxes, ECE before and after, reliability tables, per-class share right)."""
    samples = load_samples(data_dir, split)
    if not samples:
        raise ValueError(f"no {split} renders in {data_dir}")
    floor = float(detector.cfg.confidence if floor is None else floor)
    s, y, c = labelled_scores(detector, samples, floor, progress)
    cal = fit_platt(s, y)
    p = cal.probabilities(s)
    per_class = {}
    for k, name in enumerate(CLASS_NAMES):
        m = c == k
        if np.any(m):
            per_class[name] = {"boxes": int(m.sum()), "share_right": round(float(y[m].mean()), 3),
                               "mean_score": round(float(s[m].mean()), 3), "mean_probability": round(float(p[m].mean()), 3)}
    r4 = lambda rows: [{k: (round(v, 3) if isinstance(v, float) else v) for k, v in r.items()} for r in rows]  # noqa: E731
    recipe = _dataset_recipe(data_dir)
    return {
        "method": "platt",
        "slope": round(cal.slope, 6),
        "offset": round(cal.offset, 6),
        "formula": "p = 1 / (1 + exp(-(slope * logit(score) + offset)))",
        "fitted_on": {"path": project_relative(data_dir), "split": split, "images": len(samples), "score_floor": floor,
                      "boxes": int(len(s)), "right": int(y.sum()), "seed": recipe.get("seed"),
                      "dataset_command": recipe.get("command")},
        "ece_before": round(expected_calibration_error(s, y), 4),
        "ece_after": round(expected_calibration_error(p, y), 4),
        "score_for_probability": {f"{q:.2f}": round(_score_for(cal.slope, cal.offset, q), 3) for q in (0.5, 0.8, 0.9)},
        "reliability_before": r4(reliability(s, y)),
        "reliability_after": r4(reliability(p, y)),
        "per_class": per_class,
        "date": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
    }


def _dataset_recipe(data_dir: Path) -> dict[str, Any]:
    """The ``ocslam`` section of an ``ocslam dataset``'s data.yaml (command, seed; ``{}`` if none)."""
    import yaml

    try:
        data = yaml.safe_load((Path(data_dir) / "data.yaml").read_text())
    except (OSError, yaml.YAMLError):
        return {}
    recipe = data.get("ocslam") if isinstance(data, dict) else None
    return dict(recipe) if isinstance(recipe, dict) else {}


def _score_for(slope: float, offset: float, probability: float) -> float:
    """The raw score the calibration maps to ``probability``."""
    z = (np.log(probability) - np.log1p(-probability) - offset) / slope
    return float(1.0 / (1.0 + np.exp(-z)))


def write_card_calibration(model: Path, entry: dict[str, Any], command: str | None = None) -> Path:
    """Put ``entry`` as ``score_calibration`` into the card entry of ``model`` (its ``model`` or variant
    entry, found by file name; the sha256 must be the file's). Returns the card's path."""
    import yaml

    from app.config import atomic_write_text
    from app.ocslam.detector import DetectorError, file_sha256, find_model_card

    found = find_model_card(model)
    if found is None:
        raise DetectorError(f"no model card describes {model}: calibrate a model that has one")
    card_path, _ = found
    card = yaml.safe_load(card_path.read_text())
    entries = ([card["model"]] if isinstance(card.get("model"), dict) else []) + list(card.get("variants") or [])
    target = next(e for e in entries if isinstance(e, dict) and str(e.get("file")) == model.name)
    if str(target.get("sha256", "")).lower() != file_sha256(model):
        raise DetectorError(f"{model} does not match its card {card_path} (sha256): refusing to calibrate it")
    if command:
        entry = {**entry, "command": command}
    target["score_calibration"] = entry
    atomic_write_text(card_path, CARD_HEADER + yaml.safe_dump(card, sort_keys=False, width=110, allow_unicode=True))
    return card_path
