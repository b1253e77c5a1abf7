"""How often the detector boxed an object in clear view, by range and apparent size, for true and false objects.

The ghost decay and the presence evidence (principles 12, 13, 17, 22 and 36 of docs/consciousness.md) read a frame
in which an object is in clear view and no box of its class covers it as evidence against the object, within
``consciousness.decay_max_range_m``, with one ``detection_rate`` for every class, range and size. This measures
what those constants stand for, on cached sweep traces: each frame of a replay in which a tracked object passes
every clear-view test of :func:`app.ocslam.ghosts.decay_tracks` except the two it measures, the range cap (here
``--max-range``) and the apparent size (``clear_view_min_px``),
whether a box of its class covered its bearing, its range from the camera and the smaller side of its image box in
the detector's 320-px input. Each object of the final map is then labelled by the evaluation: a true object
(matched), a false one (each false-positive kind), or below the presence threshold. Tracks removed before the end
are not counted (their frames would need a truth of their own), so the true objects' rates are those of the
objects that stayed — an upper bound.

    python scripts/detection_rates.py --suite zoo-dev                      # the cached zoo-dev YOLO traces
    python scripts/detection_rates.py runs/sweep-cache/*_982[3-5]?-*/trace-*.pkl --by-class
    python scripts/detection_rates.py --suite zoo-dev --json               # the table as JSON

Dev traces only: a test world's rows are its objects' (looking at them is tuning on them).
"""

from __future__ import annotations

import argparse
import json
import pickle
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

RANGE_BINS_M = (0.0, 1.5, 2.5, 3.5, 5.0, 8.0)
SIZE_BINS_PX = (0.0, 20.0, 30.0, 45.0, 70.0, 100.0, 1e9)
#: the final objects' groups, by the evaluation's kind of each
GROUPS = {"true": lambda k: k == "tp", "false": lambda k: k.startswith("fp_"), "below": lambda k: k == "below"}


def clear_view_frames(trace_path: Path, max_range_m: float) -> list[dict]:
    """One row per final object of the trace's replay: ``world``, ``id``, ``label``, ``kind`` (``tp``, ``fp_<cause>``
    or ``below``) and ``frames``, a list of ``(range_m, side_px, boxed)`` for its frames in clear view."""
    from profile_traces import replay_config

    import app.ocslam.consciousness as consciousness_module
    import app.ocslam.ghosts as ghosts
    from app.ocslam.evaluation import evaluate_objects
    from app.ocslam.presence import occluded_by_scan, visible_share
    from app.sweep.trace import replay_trace

    with open(trace_path, "rb") as fh:
        tr = pickle.load(fh)
    cfg = replay_config(trace_path, [])
    frames: dict[int, list[tuple[float, float, bool]]] = defaultdict(list)
    decay = ghosts.decay_tracks

    def watched(tracks, areas, T_map_base, T_map_scan, beam_b, beam_r, stamp, dt, rep, c, cam):
        live = [t for t in tracks if t.footprint is not None]
        if live:
            T_base_map, T_scan_map = T_map_base.inverse(), T_map_scan.inverse()
            centers = np.array([t.footprint.center for t in live])
            heights = np.array([t.prior.height[1] for t in live])
            # the ghost decay's own view test, at this range cap and with no size test (the size table measures it)
            in_view, side_px = ghosts.in_clear_view(
                live, centers, heights, T_base_map, cam, max_range_m, float(c.clear_view_in_frame), 0.0
            )
            idx = np.flatnonzero(in_view)
            side = side_px[idx]
            if len(idx):
                bearing, rng = cam.bearing_ranges_scan(T_scan_map.transform_points(centers[idx]))
                hidden = ghosts.hidden_behind(
                    np.stack([live[k].footprint.corners for k in idx]), heights[idx], areas, T_base_map, cam,
                    float(c.occlusion_margin_m),
                )
                margin = float(c.occlusion_margin_m)
                for j, k in enumerate(idx.tolist()):
                    t = live[k]
                    if hidden[j]:
                        continue
                    # any box of its class over its bearing (the decay also lets a box explain one object only)
                    boxed = any(a.label == t.label and bool(a.contains_bearing(bearing[j : j + 1], margin=0.05)[0]) for a in areas)
                    if not boxed:  # the scan's tests: a miss only where the LIDAR sees the object
                        near = ghosts.own_near_range(t, T_map_scan) if c.clear_view_own_points else None
                        if occluded_by_scan(t.footprint, T_map_scan, beam_b, beam_r, margin, near):
                            continue
                        share = visible_share(t.footprint, T_map_scan, beam_b, beam_r, margin, t.prior.length[1], near)
                        if float(c.clear_view_visible) > 0.0 and share < float(c.clear_view_visible):
                            continue
                    frames[t.id].append((float(rng[j]), float(side[j]), boxed))
        return decay(tracks, areas, T_map_base, T_map_scan, beam_b, beam_r, stamp, dt, rep, c, cam)

    consciousness_module.decay_tracks = watched
    try:
        objs = replay_trace(tr, cfg)
    finally:
        consciousness_module.decay_tracks = decay
    ev = evaluate_objects(objs, tr.truth, tr.obstacles, cfg.consciousness.presence_threshold)
    kind: dict[int, str] = {}
    for r in ev.rows:
        if r.get("kind") == "false_positive":
            kind[r["object_id"]] = f"fp_{r.get('cause')}"
        elif r.get("matched"):
            kind[r["object_id"]] = "tp"
    return [
        {"world": tr.name, "id": o.id, "label": o.label, "kind": kind.get(o.id, "below"), "frames": frames[o.id]}
        for o in objs
    ]


def rate_table(rows: list[dict], column: int, bins: tuple[float, ...]) -> list[dict]:
    """The boxed share of the frames per bin of ``column`` (0: range, 1: size), for true, false and below-threshold
    objects: ``[{"lo", "hi", "<group>_n", "<group>_boxed"}, …]``."""
    out = []
    for lo, hi in zip(bins[:-1], bins[1:]):
        row: dict = {"lo": lo, "hi": hi}
        for name, sel in GROUPS.items():
            f = [x for r in rows if sel(r["kind"]) for x in r["frames"] if lo <= x[column] < hi]
            row[f"{name}_n"] = len(f)
            row[f"{name}_boxed"] = round(sum(x[2] for x in f) / len(f), 3) if f else None
        out.append(row)
    return out


def print_table(title: str, unit: str, table: list[dict]) -> None:
    print(f"{title:18s} {'true: frames':>13s} {'boxed':>6s} {'false: frames':>14s} {'boxed':>6s} {'below: frames':>14s} {'boxed':>6s}")
    for r in table:
        hi = "∞" if r["hi"] >= 1e8 else f"{r['hi']:g}"
        cells = []
        for g in ("true", "false", "below"):
            b = r[f"{g}_boxed"]
            cells.append(f"{r[f'{g}_n']:>13d} {('–' if b is None else f'{b:.2f}'):>6s}")
        label = f"{r['lo']:g}–{hi} {unit}"
        print(f"  {label:16s} " + " ".join(cells))


def main() -> int:
    from profile_traces import suite_traces

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("traces", nargs="*", help="trace pickles (default: the suite's in runs/sweep-cache)")
    ap.add_argument("--suite", choices=("zoo-dev",), default="zoo-dev", help="cached traces by default: zoo-dev (dev only)")
    ap.add_argument("--detector", choices=("yolo", "oracle"), default="yolo", help="the recordings' detector (default yolo)")
    ap.add_argument("--max-range", type=float, default=8.0, metavar="M", help="the range cap instead of decay_max_range_m")
    ap.add_argument("--by-class", action="store_true", help="also one range table per class (true objects)")
    ap.add_argument("--json", action="store_true", help="print the tables as one JSON object")
    a = ap.parse_args()
    files = [Path(p) for p in a.traces] or suite_traces(a.suite, a.detector)
    if not files:
        print("no traces: record them with `ocslam sweep … --cache runs/sweep-cache` first", file=sys.stderr)
        return 2
    rows = [r for f in files for r in clear_view_frames(f, a.max_range)]
    result: dict = {
        "worlds": len(files),
        "objects": {g: sum(1 for r in rows if sel(r["kind"])) for g, sel in GROUPS.items()},
        "by_range_m": rate_table(rows, 0, RANGE_BINS_M),
        "by_size_px": rate_table(rows, 1, SIZE_BINS_PX),
    }
    if a.by_class:
        result["by_class_range_m"] = {
            c: rate_table([r for r in rows if r["label"] == c], 0, RANGE_BINS_M) for c in sorted({r["label"] for r in rows})
        }
    if a.json:
        print(json.dumps(result, indent=1))
        return 0
    print(f"{result['worlds']} worlds; final objects: {result['objects']}")
    print_table("range (m)", "m", result["by_range_m"])
    print_table("apparent size", "px", result["by_size_px"])
    for c, table in result.get("by_class_range_m", {}).items():
        print_table(c, "m", table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
