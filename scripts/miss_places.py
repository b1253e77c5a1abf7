"""Where the clear misses were counted: how many an object's track took while its centre stood elsewhere.

A clear miss (principles 12–14, 17, 22, 36 of docs/consciousness.md) is a frame in which a tracked object is in
clear view and no box of its class explains it. It weighs against the object wherever the track stands *now*, but
it looked at where the track stood *then*: a track placed 0.4 m off its object, one frame old, counts misses while
the object's own boxes go to another track, and keeps them after it moved onto its object. This replays cached
sweep traces, records the track's centre at each miss, and reports for every object of the final map within
``--truth-m`` of a true object of its class but below the presence threshold how many of its misses were counted
more than ``--moved-m`` from where it ended.

    python scripts/miss_places.py runs/sweep-cache/*_982[0-5]?-*/trace-*.pkl     # the 60 random dev worlds

Dev traces only: a test world's rows are its objects' (looking at them is tuning on them).
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

    import app.ocslam.tracks as tracks
    from app.sweep.trace import replay_trace

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("traces", nargs="+", help="trace pickles (runs/sweep-cache/*/trace-*.pkl)")
    ap.add_argument("--moved-m", type=float, default=0.3, help="a miss counted farther than this from the end (m)")
    ap.add_argument("--truth-m", type=float, default=0.5, help="a true object of the class this near the end (m)")
    a = ap.parse_args()

    places: dict[int, list[tuple[float, float]]] = {}
    missed = tracks.Track.missed

    def recording_missed(self, stamp, *args, **kwargs):  # the track's centre at each clear miss
        if self.footprint is not None:
            places.setdefault(self.id, []).append((float(self.footprint.center[0]), float(self.footprint.center[1])))
        return missed(self, stamp, *args, **kwargs)

    tracks.Track.missed = recording_missed
    n_miss = n_moved = n_objects = 0
    for path in a.traces:
        places.clear()
        with open(path, "rb") as fh:
            tr = pickle.load(fh)
        cfg = replay_config(Path(path), [])
        thr = float(cfg.consciousness.presence_threshold)
        for o in replay_trace(tr, cfg):
            ms = places.get(o.id, [])
            moved = [m for m in ms if math.hypot(m[0] - o.pose.x, m[1] - o.pose.y) > a.moved_m]
            n_miss += len(ms)
            n_moved += len(moved)
            near = min((math.hypot(g.pose.x - o.pose.x, g.pose.y - o.pose.y) for g in tr.truth if g.label == o.label),
                       default=math.inf)
            if moved and o.presence < thr and near <= a.truth_m:
                n_objects += 1
                print(f"{Path(path).parent.name:32s} {o.label:10s} #{o.id:<4d} presence {o.presence:.2f}  "
                      f"misses {len(ms):3d}, {len(moved):3d} of them > {a.moved_m} m from its end")
    print(f"clear misses {n_miss}, counted > {a.moved_m} m from the track's end {n_moved}; true objects below the "
          f"threshold with such misses: {n_objects}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
