"""Record the Consciousness node's inputs on a headless run, and replay them offline.

Tuning the fusion on full simulated runs costs minutes per world; its inputs (boxes, the synchronised
scan and pose, the occupancy grid, keyframes, loop-closure corrections) do not depend on the fusion,
so a recording replays in seconds and gives the same object map and the same figures as the run.

    python scripts/fusion_replay.py record --detector oracle --out /tmp/apartment-oracle.pkl.gz
    python scripts/fusion_replay.py record --world assets/worlds/zoo/x.yaml --detector yolo --out x.pkl.gz
    python scripts/fusion_replay.py record --random-seed 99000 --detector yolo --out r99000.pkl.gz
    python scripts/fusion_replay.py replay /tmp/apartment-oracle.pkl.gz [--set consciousness.key=value]

``record`` drives the world's route (``tour`` by default) like ``ocslam bench objects``; ``replay``
prints the paper's results row and each miss. Recordings are local files (never commit them).
"""

from __future__ import annotations

import argparse
import gzip
import json
import pickle
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


class _Recorder:
    """Stands in for ``Pipeline.consciousness``: records every call, forwards it to the real node."""

    def __init__(self, node: Any, slam: Any) -> None:
        self._node = node
        self._slam = slam
        self.calls: list[tuple] = []

    def __getattr__(self, name: str) -> Any:
        return getattr(self._node, name)

    def update(self, detections, scan, T, *, stamp, grid=None, keyframe=None, robot_moved=None):
        self.calls.append(("update", detections, scan, T, stamp, grid, keyframe, robot_moved))
        return self._node.update(detections, scan, T, stamp=stamp, grid=grid, keyframe=keyframe, robot_moved=robot_moved)

    def apply_correction(self, keyframe_pose):
        poses = {}
        anchors = getattr(self._node, "_anchors", None)
        for k in list(anchors.poses if anchors is not None else {}):
            try:
                poses[k] = keyframe_pose(k)
            except (KeyError, IndexError):
                pass
        self.calls.append(("correct", poses))
        return self._node.apply_correction(keyframe_pose)


def record(args: argparse.Namespace) -> int:
    from app.commands.run import config_from_args
    from app.pipeline import Pipeline

    cfg = config_from_args(args)
    world = None
    if args.random_seed is not None:
        from app.world.generator import random_world

        world = random_world(int(args.random_seed))
    pipe = Pipeline(cfg, world=world)
    if pipe.detector is None:
        raise SystemExit(pipe.detector_error or "no detector")
    rec = _Recorder(pipe.consciousness, pipe.slam)
    pipe.consciousness = rec  # type: ignore[assignment]
    route = args.route or ("tour" if "tour" in pipe.world.routes else next(iter(pipe.world.routes)))
    pipe.follow_route(route)
    t0 = time.perf_counter()
    while pipe.time < args.duration and pipe.drive_mode == "route":
        pipe.step()
        rec._slam = pipe.slam
    pipe.consciousness = rec._node
    rep = pipe.object_report().as_dict()
    out = {
        "world": pipe.world.name,
        "detector": cfg.detector.kind,
        "mode": cfg.consciousness.mode,
        "consciousness_cfg": {f: getattr(cfg.consciousness, f) for f in cfg.consciousness.__dataclass_fields__},
        "camera": pipe.camera_model,
        "calls": rec.calls,
        "truth": pipe.truth_objects_map(),
        "obstacles": pipe.truth_obstacles_map(),
        "live_report": rep,
        "wall_s": time.perf_counter() - t0,
        "route_done": pipe.nav_status == "route done",
    }
    pipe.close()
    with gzip.open(args.out, "wb", compresslevel=3) as f:
        pickle.dump(out, f, protocol=pickle.HIGHEST_PROTOCOL)
    print(json.dumps({k: rep.get(k) for k in ("in_scene", "in_map", "tp", "fn", "precision_strict", "recall", "f1",
                                               "pos_err_mean_m")} | {"wall_s": round(out["wall_s"], 1)}))
    return 0


def load(path: str | Path) -> dict:
    with gzip.open(path, "rb") as f:
        return pickle.load(f)


def replay_data(data: dict, overrides: dict[str, Any] | None = None, cfg_mode: str | None = None):
    """Replay a recording through a fresh node; returns ``(node, ObjectReport)``."""
    from app.ocslam.config import ConsciousnessConfig
    from app.ocslam.consciousness import Consciousness
    from app.ocslam.evaluation import evaluate_objects

    cfg = ConsciousnessConfig()
    for k, v in data["consciousness_cfg"].items():
        if hasattr(cfg, k):
            setattr(cfg, k, v)
    for k, v in (overrides or {}).items():
        setattr(cfg, k, type(getattr(cfg, k))(v) if not isinstance(getattr(cfg, k), bool) else str(v).lower() in ("1", "true", "yes"))
    if cfg_mode:
        cfg.mode = cfg_mode
    node = Consciousness(cfg, data["camera"])
    for call in data["calls"]:
        if call[0] == "update":
            _, dets, scan, T, stamp, grid, kf, moved = call
            node.update(dets, scan, T, stamp=stamp, grid=grid, keyframe=kf, robot_moved=moved)
        else:
            poses = call[1]

            def kp(k, poses=poses):
                return poses[k]

            node.apply_correction(kp)
    rep = evaluate_objects(node.objects, data["truth"], data["obstacles"], cfg.presence_threshold)
    return node, rep


def replay(args: argparse.Namespace) -> int:
    overrides = {}
    for s in args.overrides or []:
        k, _, v = s.partition("=")
        overrides[k.removeprefix("consciousness.")] = v
    rows = []
    for path in args.recordings:
        data = load(path)
        t0 = time.perf_counter()
        _node, rep = replay_data(data, overrides)
        d = rep.as_dict()
        row = {k: d.get(k) for k in ("in_scene", "in_map", "tp", "fn", "fp_legs", "fp_corner", "fp_other",
                                      "precision_strict", "recall", "f1", "pos_err_mean_m")}
        row["file"] = Path(path).name
        row["replay_s"] = round(time.perf_counter() - t0, 1)
        rows.append(row)
        if args.json:
            continue
        print(json.dumps(row))
        if args.verbose:
            for r in d.get("rows", []):
                if r.get("matched") is not True or r.get("cause"):
                    print("   ", r.get("class"), r.get("true_xy"), r.get("est_xy"), r.get("matched"), r.get("cause"))
    if len(rows) > 1:
        import numpy as np

        mean = {k: round(float(np.mean([r[k] for r in rows if r[k] is not None])), 4)
                for k in ("precision_strict", "recall", "f1", "pos_err_mean_m")}
        print(json.dumps({"mean": mean, "n": len(rows)}))
    if args.json:
        print(json.dumps(rows))
    return 0


def main(argv: list[str] | None = None) -> int:
    from app.commands.run import add_config_arguments

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record")
    add_config_arguments(r)
    r.add_argument("--route", default=None)
    r.add_argument("--random-seed", type=int, default=None, help="a random world (app.world.generator.random_world) instead of --world")
    r.add_argument("--duration", type=float, default=1500.0)
    r.add_argument("--out", required=True)
    q = sub.add_parser("replay")
    q.add_argument("recordings", nargs="+")
    q.add_argument("--set", dest="overrides", action="append", default=[])
    q.add_argument("--json", action="store_true")
    q.add_argument("-v", "--verbose", action="store_true")
    args = p.parse_args(argv)
    return record(args) if args.cmd == "record" else replay(args)


if __name__ == "__main__":
    raise SystemExit(main())
