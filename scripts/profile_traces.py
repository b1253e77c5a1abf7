"""Time (and optionally profile) the consciousness on cached sweep traces, and fingerprint the maps.

The sweep's traces (``runs/sweep-cache/*/trace-*.pkl``, made by ``ocslam sweep``) are the exact
``Consciousness.update`` calls of one recording per world, so replaying them measures the fusion's
per-frame cost alone. The fingerprint (a hash of every object's class, pose, size and presence) shows
whether a change to the code kept the object maps identical. Each YOLO recording is replayed through its own
model's score calibration (:func:`replay_config`), and each world once per detector and model.

    python scripts/profile_traces.py                       # the cached zoo-dev traces, default config
    python scripts/profile_traces.py --suite zoo-test      # the held-out half (only report it)
    python scripts/profile_traces.py --profile 30          # + cProfile, top 30 functions by own time
    python scripts/profile_traces.py --profile 30 --sort cumulative   # ... by time with callees
    python scripts/profile_traces.py --set consciousness.island_threshold_m=0.2
    python scripts/profile_traces.py --detector oracle --misses   # the oracle recordings, each miss and FP (dev only)
    python scripts/profile_traces.py --suite zoo-test --causes    # the suite's misses counted by cause (no per-object rows)
    python scripts/profile_traces.py --model unrecorded          # YOLO recordings of the model before 2026-12-03 15:00
"""

from __future__ import annotations

import argparse
import cProfile
import functools
import hashlib
import pickle
import pstats
import sys
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def fingerprint(objs) -> str:
    h = hashlib.sha256()
    for o in sorted(objs, key=lambda o: (o.label, round(o.pose.x, 6), round(o.pose.y, 6))):
        h.update(f"{o.id} {o.label} {o.pose.x:.9f} {o.pose.y:.9f} {o.pose.yaw:.9f} {o.presence:.9f} "
                 f"{o.size_x:.9f} {o.size_y:.9f} {o.frames_seen}\n".encode())
    return h.hexdigest()[:12]


@functools.lru_cache(maxsize=4096)
def recording_meta(trace: Path) -> dict:
    """The ``recording.json`` of a cached trace's recording (``{}`` if unreadable); read once, read-only."""
    import json

    try:
        return dict(json.loads((trace.parent / "recording.json").read_text()))
    except (OSError, ValueError):
        return {}


def recording_detector(trace: Path) -> str:
    """The detector a cached recording was made with (its ``recording.json``), ``"?"`` if unknown."""
    return str(recording_meta(trace).get("detector", "?"))


_MODEL_DIRS = ("assets/models", "runs/detector")
_model_shas: dict[str, Path] | None = None


def recording_model(trace: Path) -> Path | None:
    """The model file a YOLO recording was made with (found by its ``detector_model_sha256`` among
    ``assets/models`` and ``runs/detector``), ``None`` for an oracle recording or a model not found here.

    A replay must read the recorded scores through *that* model's card calibration: another model's (the
    app's) maps them to the wrong probabilities."""
    global _model_shas
    sha = recording_meta(trace).get("detector_model_sha256")
    if not sha:
        return None
    if _model_shas is None:
        _model_shas = {}
        for d in _MODEL_DIRS:
            for f in sorted((ROOT / d).rglob("*.onnx")):
                _model_shas.setdefault(hashlib.sha256(f.read_bytes()).hexdigest(), f)
    return _model_shas.get(str(sha))


def replay_config(trace: Path, sets: list[str]):
    """The :class:`~app.config.Config` to replay ``trace`` with: its detector kind, for YOLO the recording's own
    model (its card's score calibration; ``detector.calibration=off`` with a warning when the model is not
    here), then ``sets`` (``SECTION.KEY=VALUE``)."""
    from app.config import Config

    cfg = Config()
    if recording_detector(trace) == "oracle":
        cfg.set("detector.kind", "oracle")
    else:
        cfg.set("detector.kind", "yolo")
        model = recording_model(trace)
        if model is not None:
            cfg.set("detector.model_path", str(model))
        else:
            print(f"warning: {trace.parent.name}: its model is not here; replayed without a score calibration",
                  file=sys.stderr)
            cfg.set("detector.calibration", "off")
    for s in sets:
        k, _, v = s.partition("=")
        cfg.set(k, v)
    return cfg


def model_matches(trace: Path, model: str, current_sha: str | None = None) -> bool:
    """Whether a YOLO recording was made with ``model``: ``any``; ``current`` (the config's model file, by
    content); ``unrecorded`` (recordings from before the model's hash was written down); or a sha256 prefix."""
    meta = recording_meta(trace)
    if model == "any" or meta.get("detector") != "yolo":
        return True
    sha = meta.get("detector_model_sha256")
    if model == "unrecorded":
        return sha is None
    if model == "current":
        return sha is not None and sha == current_sha
    return sha is not None and str(sha).startswith(model)


def suite_traces(suite: str, detector: str = "yolo", model: str = "current", cache: str = "runs/sweep-cache") -> list[Path]:
    """The cached traces (``<cache>/<world>-<key>/trace-*.pkl``) of a zoo half, or all of them,
    recorded with ``detector`` (``any``: every recording) and, for YOLO, ``model`` (:func:`model_matches`)."""
    files = sorted(Path(cache).glob("*/trace-*.pkl"))
    if detector != "any":
        files = [f for f in files if recording_detector(f) == detector]
    current = None
    if model == "current":  # the app's model, by content, read once
        from app.config import Config
        from app.sweep.suite import detector_model_sha256

        current = detector_model_sha256(Config().to_dict())
    files = [f for f in files if model_matches(f, model, current)]
    # one recording per world, detector and model: the earliest (a sweep with other settings may record a
    # world again under another cache key)
    first: dict[tuple[str, str, str], Path] = {}
    for f in sorted(files, key=lambda f: ((f.parent / "recording.json").stat().st_mtime, str(f))):
        meta = recording_meta(f)
        key = (f.parent.name.rsplit("-", 1)[0], str(meta.get("detector")), str(meta.get("detector_model_sha256")))
        first.setdefault(key, f)
    files = sorted(first.values())
    if suite == "all":
        return files
    from app.bench.objects import zoo_split

    names = set(zoo_split()[suite.split("-")[1]])
    return [f for f in files if f.parent.name.rsplit("-", 1)[0] in names]


def print_misses(ev) -> None:
    """Each false negative (with its map-side cause, :func:`~app.ocslam.evaluation.explain_misses`) and each false
    positive of one world."""
    for r in ev.rows:
        if r.get("cause") in (None, "tp"):
            continue
        fp = r.get("kind") == "false_positive"
        xy = r["est_xy"] if fp else r["true_xy"]
        who = f"#{r.get('object_id')} p={r.get('presence')}" if fp else r.get("name", "")
        print(f"    {'FP' if fp else 'FN'} {r.get('class', ''):12s} ({xy[0]:6.2f}, {xy[1]:6.2f}) {r.get('cause'):15s} "
              f"{who} {r.get('miss_detail', '')}")


def main() -> int:
    from app.ocslam.evaluation import evaluate_objects, explain_misses
    from app.sweep.trace import FuseInput, replay_trace

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("traces", nargs="*", help="trace pickles (default: the suite's in runs/sweep-cache)")
    ap.add_argument("--suite", choices=("zoo-dev", "zoo-test", "all"), default="zoo-dev",
                    help="which cached traces by default: the zoo's dev half (default), its test half, or all")
    ap.add_argument("--detector", choices=("yolo", "oracle", "any"), default="yolo",
                    help="the recordings' detector (default yolo)")
    ap.add_argument("--model", default="current", metavar="current|unrecorded|any|SHA",
                    help="YOLO recordings made with the app's current model (default, by content), before the model "
                         "was written down, any, or the model whose sha256 starts so")
    ap.add_argument("--misses", action="store_true", help="list each world's misses and false positives")
    ap.add_argument("--cache", default="runs/sweep-cache", metavar="DIR",
                    help="the sweep cache the suite's traces are read from (default runs/sweep-cache)")
    ap.add_argument("--causes", action="store_true",
                    help="count the suite's false negatives by cause and false positives by kind (a table, no per-object rows)")
    ap.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    ap.add_argument("--profile", type=int, default=0, metavar="N", help="print the top N functions (own time)")
    ap.add_argument("--sort", choices=("tottime", "cumulative"), default="tottime",
                    help="the profile's order: own time (default) or time with callees")
    a = ap.parse_args()
    files = [Path(p) for p in a.traces] or suite_traces(a.suite, a.detector, a.model, a.cache)
    if not files:
        print("no traces: run `ocslam sweep assets/sweeps/six-constants.yaml --trials 1` first", file=sys.stderr)
        return 2
    prof = cProfile.Profile() if a.profile else None
    total_s = total_frames = 0.0
    f1s = []
    causes: Counter[str] = Counter()
    for f in files:
        with open(f, "rb") as fh:
            tr = pickle.load(fh)
        cfg = replay_config(f, a.set)
        frames = sum(isinstance(e, FuseInput) for e in tr.events)
        t0 = time.process_time()
        if prof:
            prof.enable()
        objs = replay_trace(tr, cfg)
        if prof:
            prof.disable()
        dt = time.process_time() - t0
        total_s += dt
        total_frames += frames
        ev = evaluate_objects(objs, tr.truth, tr.obstacles, cfg.consciousness.presence_threshold)
        f1s.append(ev.f1)
        print(f"{tr.name:28s} {frames:5d} frames {dt:7.2f} CPU s {1e3 * dt / max(frames, 1):6.2f} ms/frame "
              f"{len(objs):3d} objects {fingerprint(objs)} F1 {ev.f1:.3f}")
        if a.misses or a.causes:
            explain_misses(ev, tr.truth, objs, None, cfg.consciousness.presence_threshold)
        if a.misses:
            print_misses(ev)
        if a.causes:
            here = Counter(f"{'FP' if r.get('kind') == 'false_positive' else 'FN'} {r.get('cause')}"
                           for r in ev.rows if r.get("cause") not in (None, "tp"))
            causes.update(here)
            if here:
                print("    " + ", ".join(f"{k} {v}" for k, v in sorted(here.items())))
    print(f"{'total':28s} {int(total_frames):5d} frames {total_s:7.2f} CPU s {1e3 * total_s / max(total_frames, 1):6.2f} ms/frame "
          f"mean F1 {sum(f1s) / len(f1s):.4f}")
    if a.causes:
        print("causes: " + ", ".join(f"{k} {v}" for k, v in sorted(causes.items())))
    if prof:
        pstats.Stats(prof).sort_stats(a.sort).print_stats(a.profile)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
