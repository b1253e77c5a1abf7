"""``ocslam bench objects``: the object map against ground truth — the paper's results table, measured.

    ocslam bench objects --mode seed --detector yolo          # one world (the paper's apartment) and its tour
    ocslam bench objects --worlds 10 --detector yolo          # 10 random worlds (rooms family): per-world and mean
    ocslam bench objects --suite zoo-dev --detector oracle    # a suite: per-world table, mean, causes of misses
    ocslam bench objects --suite random --workers 2 --json    # 10 worlds of the new layout families (seeds 99000…)

Suites (``--suite``): ``zoo-dev`` and ``zoo-test`` are the halves of the hand-written world zoo
(``assets/worlds/zoo/split.yaml``, documented in ``assets/worlds/zoo/README.md``: tune on dev, only
report test); ``random`` is ``--suite-worlds`` (10) worlds of the corridor, L-shaped and open-plan
families (:mod:`app.world.layouts`), seeds ``--world-seed`` (99000) onwards, the family cycling with the
seed. Worlds run in ``--workers`` processes (2 by default); each world's run depends only on its world
and the config (``sim.seed``), so a suite gives the same figures serial or parallel.

Every false negative gets a cause (:data:`app.ocslam.evaluation.MISS_CAUSES`): the run logs, per
camera frame, which true objects were in view (true camera pose, walls and tall furniture occlude),
which a box of their class covered and which had LIDAR returns inside such a box; the final map says
whether a missed object was merged into another or tracked below the presence threshold.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from app.bench.common import print_json, table
from app.commands.run import add_config_arguments, config_from_args

KEYS = ("in_scene", "in_map", "tp", "fn", "fp_legs", "fp_corner", "fp_other", "precision_strict",
        "precision_lenient", "recall", "f1", "pos_err_mean_m", "pos_err_max_m")
SUITES = ("zoo-dev", "zoo-test", "random")
#: the zoo and its dev/test split
ZOO_DIR = Path(__file__).resolve().parents[2] / "assets" / "worlds" / "zoo"
#: families of the ``random`` suite, cycled with the seed
RANDOM_FAMILIES = ("corridor", "lshape", "openplan")


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_config_arguments(p)
    p.add_argument("--route", default=None, help="route (default: sim.route, 'tour')")
    p.add_argument("--worlds", type=int, default=0, help="run N random worlds (rooms family) instead of --world")
    p.add_argument("--world-seed", type=int, default=99000,
                   help="first random world seed (with --worlds or --suite random); 99000… are worlds the detector "
                        "never saw (its training used 1000…1039)")
    p.add_argument("--suite", choices=SUITES, default=None,
                   help="zoo-dev / zoo-test (assets/worlds/zoo/README.md) or random (the new layout families)")
    p.add_argument("--suite-worlds", type=int, default=10, help="number of worlds of --suite random")
    p.add_argument("--only", action="append", default=[], metavar="NAME",
                   help="with --suite: run only these worlds (by name; repeatable)")
    p.add_argument("--workers", type=int, default=2, help="worker processes for --suite and --worlds (1: in this process)")
    p.add_argument("--jsonl", type=Path, default=None,
                   help="with --suite/--worlds: append each world's report to this file as soon as it is done "
                        "(a long suite that is stopped keeps the worlds it finished)")
    p.add_argument("--duration", type=float, default=1500.0, help="max sim seconds per world")
    p.add_argument("--json", action="store_true")


# ----------------------------------------------------------------------------------------------
# One world
# ----------------------------------------------------------------------------------------------


class _FrameLogger:
    """Feeds an :class:`~app.ocslam.evaluation.ObservationLog` from a running pipeline (ground truth:
    the evaluation's side only; nothing goes back into the pipeline)."""

    def __init__(self, pipe: Any, max_range_m: float = 4.0) -> None:
        from app.ocslam.evaluation import ObservationLog
        from app.world.tour import occluders_for

        self.pipe = pipe
        self.truth = pipe.sim.ground_truth_objects()  # world frame, the order of truth_objects_map()
        self.log = ObservationLog(len(self.truth))
        self.occluders = occluders_for(pipe.world)
        self.max_range_m = max_range_m
        T_bc = pipe.robot_model.T_base_camera_optical
        self.cam_offset = (float(T_bc[0, 3]), float(T_bc[1, 3]))
        self.T_world_map = pipe.T_map_world.inverse()
        self._last = None

    def _true_world_pose(self, stamp: float):
        log = self.pipe.truth_log
        if not log:
            return None
        # truth_log is appended in time order; nearest entry to the stamp
        stamps = [s for s, _, _ in log[-40:]]
        k = int(np.argmin(np.abs(np.asarray(stamps) - stamp)))
        return self.T_world_map @ log[-40:][k][1]

    def poll(self) -> None:
        from app.ocslam.messages import CLASS_NAMES, CameraInfo
        from app.ocslam.se2 import Pose2
        from app.ocslam.visibility import in_view_matrix

        dets = self.pipe.fusion.detections
        if dets is None or dets is self._last:
            return
        self._last = dets
        T_wb = self._true_world_pose(dets.stamp)
        if T_wb is None:
            return
        cam = T_wb @ Pose2(self.cam_offset[0], self.cam_offset[1], 0.0)
        pose = np.array([cam.x, cam.y, cam.yaw])
        cfg = self.pipe.cfg
        w = int(dets.image_width)
        h = max(1, int(getattr(dets, "image_height", 0) or round(w * cfg.camera.height / cfg.camera.width)))
        info = CameraInfo.from_fov(w, h, cfg.camera.hfov_rad)
        iv = in_view_matrix(pose[None, :], [t.footprint for t in self.truth], self.occluders, cfg.camera.hfov_rad,
                            max_range_m=self.max_range_m)[0]
        boxes = [(CLASS_NAMES[b.class_id], float(b.x1), float(b.x2)) for b in dets.boxes]
        pts = None
        scan = self.pipe.scans.nearest(dets.stamp, 0.25)
        if scan is not None:
            T_ws = self._true_world_pose(scan.stamp)
            if T_ws is not None:
                pts = (T_ws @ self.pipe.T_base_scan).transform_points(scan.points())
        self.log.add_frame(pose, self.truth, iv, boxes, info.fx, info.cx, w, pts)


def run_world(cfg, route: str | None, duration: float, world=None, explain: bool = True) -> dict:
    """Drive one world's route headless and score the object map; with ``explain``, every false
    negative row carries a ``cause`` (and ``miss_detail``) and ``miss_causes`` counts them."""
    from app.ocslam.evaluation import explain_misses
    from app.pipeline import Pipeline

    pipe = Pipeline(cfg, world=world)
    if pipe.detector is None:
        raise RuntimeError(pipe.detector_error or "no detector configured")
    pipe.follow_route(route or cfg.sim.route)
    logger = _FrameLogger(pipe) if explain else None
    t0 = time.perf_counter()
    while pipe.time < duration and pipe.drive_mode == "route":
        pipe.step()
        if logger is not None:
            logger.poll()
    wall = time.perf_counter() - t0
    report = pipe.object_report()
    causes = None
    if logger is not None:
        causes = explain_misses(report, pipe.truth_objects_map(), pipe.objects_in_map(), logger.log,
                                cfg.consciousness.presence_threshold)
    rep = report.as_dict()
    if causes is not None:
        rep["miss_causes"] = causes
        rep["frames_logged"] = logger.log.frames
    rep["world"] = pipe.world.name
    rep["sim_time_s"] = round(pipe.time, 1)
    rep["wall_s"] = round(wall, 1)
    rep["route_done"] = pipe.nav_status == "route done"
    rep["collisions"] = int(getattr(pipe.sim, "collisions", 0))
    pipe.close()
    return rep


# ----------------------------------------------------------------------------------------------
# Suites
# ----------------------------------------------------------------------------------------------


def zoo_split(path: Path | None = None) -> dict[str, list[str]]:
    """``{"dev": [world names], "test": [...]}`` from ``assets/worlds/zoo/split.yaml``."""
    import yaml

    p = path or ZOO_DIR / "split.yaml"
    data = yaml.safe_load(p.read_text(encoding="utf-8"))
    if not isinstance(data, dict) or not all(isinstance(data.get(k), list) for k in ("dev", "test")):
        raise ValueError(f"{p}: expected mappings 'dev' and 'test' with lists of world names")
    return {"dev": [str(n) for n in data["dev"]], "test": [str(n) for n in data["test"]]}


def suite_jobs(suite: str, *, n_random: int = 10, first_seed: int = 99000) -> list[dict[str, Any]]:
    """The worlds of a suite as jobs ``{"name", "file"}`` (zoo) or ``{"name", "seed", "family"}``."""
    if suite in ("zoo-dev", "zoo-test"):
        names = zoo_split()[suite.split("-")[1]]
        return [{"name": n, "file": str(ZOO_DIR / f"{n}.yaml")} for n in names]
    if suite == "random":
        return [{"name": f"{RANDOM_FAMILIES[i % len(RANDOM_FAMILIES)]} {first_seed + i}", "seed": first_seed + i,
                 "family": RANDOM_FAMILIES[i % len(RANDOM_FAMILIES)]} for i in range(n_random)]
    raise ValueError(f"unknown suite {suite!r} (suites: {', '.join(SUITES)})")


def _job_world(job: dict[str, Any]):
    if "file" in job:
        from app.world.format import load_world

        return load_world(job["file"])
    from app.world.generator import generate

    return generate(job.get("family", "rooms"), int(job["seed"]))


def _run_job(cfg_dict: dict, job: dict[str, Any], duration: float) -> dict:
    """One world in a worker process (the config travels as a dict)."""
    from app.config import Config

    cfg = Config.from_dict(cfg_dict)
    try:
        world = _job_world(job)
        route = "tour" if "tour" in world.routes else next(iter(world.routes))
        rep = run_world(cfg, route, duration, world)
    except Exception as e:  # one broken world must not lose the others' figures
        return {"job": job, "error": f"{type(e).__name__}: {e}"}
    rep["job"] = job
    return rep


def run_jobs(cfg, jobs: list[dict[str, Any]], duration: float, workers: int = 2, quiet: bool = False,
             jsonl: Path | None = None) -> list[dict]:
    """Run every job (in ``workers`` processes; 1: here), results in the jobs' order; each result is
    also appended to ``jsonl`` (one JSON object a line) as soon as its world is done."""
    import json

    cfg_dict = cfg.to_dict()

    def done(k: int, r: dict) -> None:
        if jsonl is not None:
            with open(jsonl, "a", encoding="utf-8") as f:
                f.write(json.dumps(r, default=float) + "\n")
        if not quiet:
            msg = r.get("error") or f"F1 {r.get('f1', 0):.3f}, {r.get('wall_s')} s"
            print(f"world {k + 1}/{len(jobs)} ({jobs[k]['name']}): {msg}", file=sys.stderr, flush=True)

    if workers <= 1 or len(jobs) <= 1:
        out = []
        for k, job in enumerate(jobs):
            out.append(_run_job(cfg_dict, job, duration))
            done(k, out[-1])
        return out
    import multiprocessing as mp
    from concurrent.futures import as_completed

    ctx = mp.get_context("spawn")  # pybullet and onnxruntime do not survive a fork
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as ex:
        futs = {ex.submit(_run_job, cfg_dict, job, duration): k for k, job in enumerate(jobs)}
        results: dict[int, dict] = {}
        for f in as_completed(futs):
            k = futs[f]
            results[k] = f.result()
            done(k, results[k])
        return [results[k] for k in range(len(jobs))]


def summarize(per_world: list[dict]) -> dict[str, Any]:
    """Mean of :data:`KEYS` over the worlds that ran, and the causes of misses and false positives summed."""
    from app.ocslam.evaluation import MISS_CAUSES

    ok = [r for r in per_world if "error" not in r]
    vals = {k: [r[k] for r in ok if r.get(k) is not None] for k in KEYS}
    mean = {k: float(np.mean(v)) if v else math.nan for k, v in vals.items()}
    miss = {c: int(sum(r.get("miss_causes", {}).get(c, 0) for r in ok)) for c in MISS_CAUSES}
    fp = {c: int(sum(r.get(f"fp_{c}", 0) for r in ok)) for c in ("legs", "corner", "other")}
    return {"mean": mean, "miss_causes": miss, "fp_causes": fp, "worlds_ok": len(ok), "worlds_failed": len(per_world) - len(ok)}


def _row(name: str, d: dict) -> list:
    return [name] + [d.get(k) for k in KEYS]


def print_suite(title: str, per_world: list[dict], summary: dict[str, Any]) -> None:
    from app.ocslam.evaluation import MISS_CAUSES

    headers = ["world"] + list(KEYS)
    rows = []
    for r in per_world:
        name = r["job"]["name"] if "job" in r else r.get("world", "?")
        rows.append([name, f"ERROR: {r['error']}"] + [None] * (len(KEYS) - 1) if "error" in r else _row(name, r))
    rows.append(_row("mean", summary["mean"]))
    table(headers, rows, title=title)
    print()
    cause_rows = []
    for r in per_world:
        if "error" in r:
            continue
        mc = r.get("miss_causes", {})
        cause_rows.append([r["job"]["name"]] + [mc.get(c, 0) for c in MISS_CAUSES]
                          + [r.get("fp_legs", 0), r.get("fp_corner", 0), r.get("fp_other", 0)])
    cause_rows.append(["total"] + [summary["miss_causes"][c] for c in MISS_CAUSES]
                      + [summary["fp_causes"][c] for c in ("legs", "corner", "other")])
    table(["world"] + [f"FN {c}" for c in MISS_CAUSES] + ["FP legs", "FP corner", "FP other"], cause_rows,
          title="Causes of misses (FN) and false positives (FP)")
    print()
    misses = [(r["job"]["name"], row.get("name") or row.get("class"), row.get("class"), row.get("cause"), row.get("miss_detail", ""))
              for r in per_world if "error" not in r for row in r.get("rows", []) if row.get("kind") == "truth" and not row.get("matched")]
    fps = [(r["job"]["name"], row.get("class"), row.get("est_xy"), row.get("cause"), f"presence {row.get('presence')}")
           for r in per_world if "error" not in r for row in r.get("rows", []) if row.get("kind") == "false_positive"]
    if misses:
        table(["world", "missed object", "class", "cause", "detail"], misses, title="Missed objects")
        print()
    if fps:
        table(["world", "false object", "at (map)", "cause", "detail"], fps, title="False positives")


def run(args: argparse.Namespace) -> int:
    from app.ocslam.evaluation import PAPER_ROW

    cfg = config_from_args(args)
    headers = ["run"] + list(KEYS)
    command = "ocslam bench objects " + " ".join(sys.argv[3:] if sys.argv[1:3] == ["bench", "objects"] else sys.argv[1:])
    if args.suite or args.worlds:
        if args.suite:
            jobs = suite_jobs(args.suite, n_random=args.suite_worlds, first_seed=args.world_seed)
            if args.only:
                jobs = [j for j in jobs if j["name"] in set(args.only)]
            label = args.suite
        else:
            jobs = [{"name": f"seed {args.world_seed + i}", "seed": args.world_seed + i, "family": "rooms"}
                    for i in range(args.worlds)]
            label = f"{args.worlds} random worlds (rooms)"
        t0 = time.perf_counter()
        per_world = run_jobs(cfg, jobs, args.duration, workers=max(1, int(args.workers)), jsonl=args.jsonl)  # progress: stderr
        summary = summarize(per_world)
        out = {"suite": label, "mode": cfg.consciousness.mode, "detector": cfg.detector.kind, "sim_seed": cfg.sim.seed,
               "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "command": command,
               "wall_s": round(time.perf_counter() - t0, 1), "worlds": per_world, **summary,
               "mean_f1": summary["mean"]["f1"]}
        if args.json:
            print_json(out)
            return 0 if not summary["worlds_failed"] else 1
        print_suite(f"Objects on {label} ({cfg.consciousness.mode}, {cfg.detector.kind}; {out['date']})", per_world, summary)
        return 0 if not summary["worlds_failed"] else 1
    rep = run_world(cfg, args.route, args.duration)
    rep["mode"] = cfg.consciousness.mode
    rep["detector"] = cfg.detector.kind
    if args.json:
        print_json(rep)
        return 0
    table(headers, [_row("paper (Webots, YOLOv8n)", PAPER_ROW), _row(f"ours ({rep['mode']}, {rep['detector']})", rep)],
          title=f"Objects on {rep['world']} ({rep['sim_time_s']} sim s, route done: {rep['route_done']})")
    print()
    table(["class", "true x, y", "estimated x, y", "matched", "cause", "detail"],
          [(r.get("class"), r.get("true_xy"), r.get("est_xy"), r.get("matched"), r.get("cause"), r.get("miss_detail", ""))
           for r in rep.get("rows", [])])
    return 0
