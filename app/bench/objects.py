"""``ocslam bench objects``: the object map against ground truth — the paper's results table, measured.

    ocslam bench objects --mode seed --detector yolo          # one world (the paper's apartment) and its tour
    ocslam bench objects --worlds 10 --detector yolo          # 10 random worlds: per-world and mean figures
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from app.bench.common import print_json, table
from app.commands.run import add_config_arguments, config_from_args

KEYS = ("in_scene", "in_map", "tp", "fn", "fp_legs", "fp_corner", "fp_other", "precision_strict",
        "precision_lenient", "recall", "f1", "pos_err_mean_m", "pos_err_max_m")


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_config_arguments(p)
    p.add_argument("--route", default=None, help="route (default: sim.route, 'tour')")
    p.add_argument("--worlds", type=int, default=0, help="run N random worlds instead of --world")
    p.add_argument("--world-seed", type=int, default=99000,
                   help="first random world seed (with --worlds); 99000… are worlds the detector never saw "
                        "(its training used 1000…1039)")
    p.add_argument("--duration", type=float, default=1500.0, help="max sim seconds per world")
    p.add_argument("--json", action="store_true")


def run_world(cfg, route: str | None, duration: float, world=None) -> dict:
    from app.pipeline import Pipeline

    pipe = Pipeline(cfg, world=world)
    if pipe.detector is None:
        raise RuntimeError(pipe.detector_error or "no detector configured")
    pipe.follow_route(route or cfg.sim.route)
    t0 = time.perf_counter()
    while pipe.time < duration and pipe.drive_mode == "route":
        pipe.step()
    wall = time.perf_counter() - t0
    rep = pipe.object_report().as_dict()
    rep["world"] = pipe.world.name
    rep["sim_time_s"] = round(pipe.time, 1)
    rep["wall_s"] = round(wall, 1)
    rep["route_done"] = pipe.nav_status == "route done"
    rep["collisions"] = int(getattr(pipe.sim, "collisions", 0))
    pipe.close()
    return rep


def _row(name: str, d: dict) -> list:
    return [name] + [d.get(k) for k in KEYS]


def run(args: argparse.Namespace) -> int:
    from app.ocslam.evaluation import PAPER_ROW

    cfg = config_from_args(args)
    headers = ["run"] + list(KEYS)
    if args.worlds:
        from app.worlds import dump_world, random_world

        per_world = []
        for i in range(args.worlds):
            seed = args.world_seed + i
            world = random_world(seed)
            print(f"world {i + 1}/{args.worlds} (seed {seed})…", file=sys.stderr, flush=True)
            rep = run_world(cfg, "tour" if "tour" in world.routes else next(iter(world.routes)), args.duration, world)
            rep["world_seed"] = seed
            per_world.append(rep)
        mean = {k: float(np.mean([r[k] for r in per_world if r.get(k) is not None])) for k in KEYS}
        out = {"mode": cfg.consciousness.mode, "detector": cfg.detector.kind, "worlds": per_world, "mean": mean,
               "mean_f1": mean["f1"]}
        if args.json:
            print_json(out)
            return 0
        rows = [_row(f"seed {r['world_seed']}", r) for r in per_world] + [_row("mean", mean)]
        table(headers, rows, title=f"Objects over {args.worlds} random worlds ({cfg.consciousness.mode}, {cfg.detector.kind})")
        return 0
    rep = run_world(cfg, args.route, args.duration)
    rep["mode"] = cfg.consciousness.mode
    rep["detector"] = cfg.detector.kind
    if args.json:
        print_json(rep)
        return 0
    table(headers, [_row("paper (Webots, YOLOv8n)", PAPER_ROW), _row(f"ours ({rep['mode']}, {rep['detector']})", rep)],
          title=f"Objects on {rep['world']} ({rep['sim_time_s']} sim s, route done: {rep['route_done']})")
    print()
    table(["class", "true x, y", "estimated x, y", "matched", "cause"],
          [(r.get("class"), r.get("true_xy"), r.get("est_xy"), r.get("matched"), r.get("cause")) for r in rep.get("rows", [])])
    return 0
