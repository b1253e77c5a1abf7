"""The life of one tracked object in a cached sweep trace: its state after every frame that had it, the frame's
boxes, and the ground truth near where it ended (dev worlds only: looking at a test world's objects is tuning
on it).

    python scripts/profile_traces.py --suite zoo-dev --misses          # find a false positive's id (#N)
    python scripts/track_life.py runs/sweep-cache/<world>-<key>/trace-<h>.pkl N [--set SECTION.KEY=VALUE ...]
    python scripts/track_life.py TRACE 0 --at 1.64,3.79   # which tracks ever stood near a missed object, then
                                                          # the life of track N (-1: none)

Each row: stamp, ``T_map_base``, presence, soft-decision frames, boxed frames, clear misses, footprint centre and
size (the trace's map frame: start-relative), whether this frame updated it and with which box (its index in the
frame's boxes), then the frame's boxes ``(class, confidence, x1, y1, x2, y2)`` at the detector threshold.
"""

from __future__ import annotations

import argparse
import math
import pickle
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))


def main() -> int:
    from profile_traces import replay_config

    from app.sweep.trace import Correction, filter_detections, replay_trace

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("trace", help="a trace pickle (runs/sweep-cache/*/trace-*.pkl)")
    ap.add_argument("track", type=int, help="the track's id (the #N of profile_traces.py --misses)")
    ap.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    ap.add_argument("--near", type=float, default=1.5, help="list ground-truth objects this close to its end (m)")
    ap.add_argument("--at", default=None, metavar="X,Y", help="also list every track that came within 0.5 m of X,Y "
                    "(trace frame), with its class, closest approach and whether it is in the final map")
    a = ap.parse_args()
    with open(a.trace, "rb") as fh:
        tr = pickle.load(fh)
    cfg = replay_config(Path(a.trace), a.set)  # the recording's detector and its model's score calibration
    conf = float(cfg.detector.confidence)
    at = tuple(float(v) for v in a.at.split(",")) if a.at else None
    near_at: dict[int, tuple[float, str, float]] = {}  # track id → (closest distance, class, stamp)

    def watch(ev, cons) -> None:
        if isinstance(ev, Correction):
            print("        loop-closure correction")
            return
        if at is not None:
            for u in cons._tracks:
                if u.footprint is not None:
                    d = math.hypot(u.footprint.center[0] - at[0], u.footprint.center[1] - at[1])
                    if d < 0.5 and d < near_at.get(u.id, (math.inf, "", 0.0))[0]:
                        near_at[u.id] = (d, u.label, ev.stamp)
        t = next((t for t in cons._tracks if t.id == a.track), None)
        if t is None or t.footprint is None:
            return
        T, fp = ev.T_map_base, t.footprint
        box = t.boxes.get(ev.stamp)
        boxes = [(b.label, round(b.confidence, 2), int(b.x1), int(b.y1), int(b.x2), int(b.y2)) for b in filter_detections(ev.detections, conf).boxes]
        print(f"{ev.stamp:8.2f} T=({T.x:5.2f},{T.y:5.2f},{T.yaw:5.2f}) p={t.presence:.2f} f={t.frames} boxed={t.detections} "
              f"missed={t.misses} c=({fp.center[0]:.2f},{fp.center[1]:.2f}) {fp.size_x:.2f}×{fp.size_y:.2f} "
              f"{'box ' + str(box) if box is not None else '-'} {boxes}")

    objects = replay_trace(tr, cfg, on_event=watch)
    final_ids = {o.id for o in objects}
    for tid, (d, label, stamp) in sorted(near_at.items()):
        print(f"near {at}: track {tid} {label} came within {d:.2f} m at {stamp:.2f} s; "
              f"{'in the final map' if tid in final_ids else 'not in the final map'}")
    o = next((o for o in objects if o.id == a.track), None)
    if o is None:
        print(f"track {a.track} is not in the final map")
        return 1
    print(f"final: {o.label} at ({o.pose.x:.2f}, {o.pose.y:.2f}) presence {o.presence:.2f} (map frame)")
    for g in tr.truth:
        d = math.hypot(g.pose.x - o.pose.x, g.pose.y - o.pose.y)
        if d < a.near:
            print(f"  truth {g.label:12s} ({g.pose.x:.2f}, {g.pose.y:.2f}) {d:.2f} m")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
