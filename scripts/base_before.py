"""How far in front of a face the boxes put an open frame's base, against where the true bookcase stands.

Principle 42 of docs/consciousness.md (``consciousness.far_face``): a bookcase seen as one face from one side is
completed towards the robot when its boxes' bottom edges put its base more than half its depth in front of that face
(``footprint_estimate._base_before``). This replays cached sweep traces, records that distance at every such
decision, and splits the records by the true bookcase nearest the points (within 1 m): *far* where it reaches more
than ``--front-m`` in front of the face (the face was its far side), *near* otherwise; it prints the percentiles of
each.

    python scripts/base_before.py runs/sweep-cache/*_982[0-5]?-*/trace-*.pkl     # the 60 random dev worlds

Dev traces only (the split uses the ground truth: looking at a test world's is tuning on it).
"""

from __future__ import annotations

import argparse
import math
import pickle
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))


def main() -> int:
    from profile_traces import replay_config

    import app.ocslam.footprint_estimate as fe
    from app.sweep.trace import replay_trace

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("traces", nargs="+", help="trace pickles (runs/sweep-cache/*/trace-*.pkl)")
    ap.add_argument("--front-m", type=float, default=0.3, help="the true bookcase reaches this far in front: far side")
    a = ap.parse_args()

    rows: list[tuple[float, float]] = []
    truth: list = []
    base_before = fe._base_before

    def recording(ev, axis, face, side):  # the decision's value, and where the true bookcase stands
        r = base_before(ev, axis, face, side)
        if math.isfinite(r) and len(ev.points):
            m = ev.points.mean(axis=0)
            near = [(math.hypot(g.pose.x - m[0], g.pose.y - m[1]), g) for g in truth if g.label == "shelf"]
            if near:
                d, g = min(near, key=lambda x: x[0])
                if d < 1.0:
                    rows.append((r, float((side * (np.asarray(g.footprint) @ axis - face)).max())))
        return r

    fe._base_before = recording
    for path in a.traces:
        with open(path, "rb") as fh:
            tr = pickle.load(fh)
        truth[:] = tr.truth
        replay_trace(tr, replay_config(Path(path), []))
    if not rows:
        print("no one-sided open-frame completions in these traces")
        return 0
    v = np.array(rows)
    far = v[:, 1] > a.front_m
    q = [5, 10, 25, 50, 75, 90, 95]
    print(f"decisions {len(v)}: face was the far side {int(far.sum())}, the near side {int((~far).sum())}")
    for name, sel in (("far side", far), ("near side", ~far)):
        if sel.any():
            print(f"{name:9s} base before the face, percentiles {q}: {np.percentile(v[sel, 0], q).round(2).tolist()} m")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
