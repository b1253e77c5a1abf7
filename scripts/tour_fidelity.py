"""How closely each recorded zoo tour passed its waypoints: the route follower's fidelity, per recording.

A waypoint the driven path never came near is a look the tour planner added and the follower skipped, so the object
it was for may have been seen from farther than the tour meant (``docs/navigation.md``, *Routes*). Reads the cached
sweep recordings (``runs/sweep-cache/<world>-<key>/``: ``recording.json`` and the trace's ``T_map_base`` per frame;
the trace's map frame starts at the world's ``start``).

    python scripts/tour_fidelity.py                          # every cached zoo recording
    python scripts/tour_fidelity.py --cache DIR --over 0.35  # another cache; waypoints missed by more than 0.35 m
"""

from __future__ import annotations

import argparse
import json
import math
import pickle
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def missed_waypoints(trace_path: Path, world_file: Path, over_m: float) -> tuple[int, list[tuple[int, float]]]:
    """``(waypoints, [(index, distance m)])``: the tour's waypoints the recording's path passed farther than ``over_m``."""
    from app.ocslam.se2 import Pose2
    from app.sweep.trace import FuseInput
    from app.world.format import load_world

    world = load_world(world_file)
    with open(trace_path, "rb") as fh:
        tr = pickle.load(fh)
    path = np.array([[e.T_map_base.x, e.T_map_base.y] for e in tr.events if isinstance(e, FuseInput)]).reshape(-1, 2)
    s = world.start
    T_map_world = Pose2(s.x, s.y, s.yaw).inverse()  # the trace's map frame starts at the world's start
    tour = T_map_world.transform_points(np.asarray(world.routes["tour"], dtype=np.float64))
    if not len(path):
        return len(tour), [(i, math.inf) for i in range(len(tour))]
    d = np.hypot(tour[:, None, 0] - path[None, :, 0], tour[:, None, 1] - path[None, :, 1]).min(axis=1)
    return len(tour), [(i, round(float(v), 2)) for i, v in enumerate(d) if v > over_m]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", default="runs/sweep-cache", help="the sweep cache (default runs/sweep-cache)")
    ap.add_argument("--over", type=float, default=0.35, metavar="M", help="a waypoint passed farther than this is missed")
    a = ap.parse_args()
    zoo = ROOT / "assets" / "worlds" / "zoo"
    total = missed = 0
    for rec in sorted(Path(a.cache).glob("*/recording.json")):
        world_file = zoo / f"{rec.parent.name.rsplit('-', 1)[0]}.yaml"
        traces = sorted(rec.parent.glob("trace-*.pkl"))
        if not world_file.is_file() or not traces:
            continue
        detector = json.loads(rec.read_text()).get("detector", "?")
        n, miss = missed_waypoints(traces[0], world_file, a.over)
        total += 1
        missed += bool(miss)
        print(f"{world_file.stem:22s} {detector:7s} {n:3d} waypoints, {len(miss)} missed {miss}")
    print(f"{missed} of {total} recordings missed a waypoint by more than {a.over} m")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
