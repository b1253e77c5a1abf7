"""``ocslam bench loop``: the complete loop headless on the apartment tour, per-stage time and real-time factor.

Physics, LIDAR, camera rendering (at the detector's input size unless ``--render-width``), detector,
SLAM and consciousness all run, with LIDAR and camera at 5 Hz. Targets: ≥ ×10 real time on 2 cores,
≥ ×4 with the camera at 640×480 (``--render-width 0``).

    ocslam bench loop --renderer tiny --json        # TinyRenderer, stages in parallel
    ocslam bench loop --renderer egl --sequential   # EGL, every stage in the loop thread
    ocslam bench loop --record                      # + the same run recording a rosbag2 bag: its cost
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

from app.bench.common import print_json, table
from app.commands.run import add_config_arguments, config_from_args


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_config_arguments(p)
    p.add_argument("--route", default=None, help="route to follow (default: sim.route)")
    p.add_argument("--duration", type=float, default=120.0, help="sim seconds to run")
    p.add_argument("--render-width", type=int, default=None,
                   help="camera render width (default: the detector's input width, as the detector would downscale anyway)")
    p.add_argument("--renderer", choices=("auto", "egl", "tiny"), default=None,
                   help="camera renderer (default: sim.renderer, auto = EGL where it loads)")
    p.add_argument("--sequential", action="store_true",
                   help="run the detector, SLAM and the consciousness in the loop thread (sim.parallel_stages=false)")
    p.add_argument("--record", action="store_true",
                   help="run twice, without and with a rosbag2 recorder (a temporary bag), and report its cost")
    p.add_argument("--json", action="store_true")


def measure(cfg, *, route: str | None, duration: float, record: Path | None = None) -> dict:
    """One run; ``record``: a new bag folder the run is recorded into (its writing is part of the run)."""
    from app.pipeline import Pipeline

    pipe = Pipeline(cfg)
    if pipe.detector_error and cfg.detector.kind == "yolo":
        raise RuntimeError(pipe.detector_error)
    pipe.follow_route(route or cfg.sim.route)
    rec = None
    if record is not None:
        from app.ros2.recorder import attach

        rec = attach(pipe, record)
    t0 = time.perf_counter()
    while pipe.time < duration:  # a finished route leaves the robot parked; sensors and estimators keep running
        pipe.step()
    if rec is not None:
        from app.ros2.recorder import detach

        detach(pipe, rec)  # waits for the stages in flight and finishes the bag
    pipe.wait_stages()  # the jobs still in flight belong to the run
    wall = time.perf_counter() - t0
    stages_call = pipe.timer.per_call_ms()
    stages_sim = pipe.timer.per_sim_second_ms(pipe.time)
    res = {
        "sim_time_s": round(pipe.time, 2),
        "wall_s": round(wall, 3),
        "real_time_factor": round(pipe.time / wall, 3),
        "stages_ms": {k: round(v, 3) for k, v in stages_call.items()},
        "stages_ms_per_sim_s": {k: round(v, 2) for k, v in stages_sim.items()},
        "calls": dict(pipe.timer.calls),
        "render_size": list(pipe.camera_render_size()),
        "camera_size": list(pipe.camera_render_size()),
        "renderer": pipe.renderer,
        "renderer_note": pipe.renderer_note,
        "parallel_stages": pipe.jobs.parallel,
        "detector": cfg.detector.kind,
        "lidar_hz": cfg.lidar.rate_hz,
        "camera_hz": cfg.camera.rate_hz,
    }
    pipe.close()
    return res


def run(args: argparse.Namespace) -> int:
    cfg = config_from_args(args)
    if args.renderer is not None:
        cfg.set("sim.renderer", args.renderer)
    if args.sequential:
        cfg.set("sim.parallel_stages", False)
    if args.render_width is not None:
        cfg.set("camera.render_width", args.render_width)
    elif not cfg.camera.render_width and cfg.detector.kind == "yolo":
        try:
            from app.config import resolve_path
            from app.ocslam.detector import Detector

            cfg.set("camera.render_width", int(Detector(cfg.detector, resolve_path(cfg.detector.model_path)).input_size[0]))
        except Exception:
            cfg.set("camera.render_width", 320)
    if args.record:
        tmp = Path(tempfile.mkdtemp(prefix="ocslam-bench-loop-"))
        try:
            off = measure(cfg, route=args.route, duration=args.duration)
            res = measure(cfg, route=args.route, duration=args.duration, record=tmp / "bag")
            res["bag_mb"] = round(sum(f.stat().st_size for f in (tmp / "bag").iterdir()) / 1e6, 2)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        res["recording"] = True
        res["real_time_factor_without_recording"] = off["real_time_factor"]
        res["recording_cost_pct"] = round(100.0 * (1.0 - res["real_time_factor"] / off["real_time_factor"]), 1)
    else:
        res = measure(cfg, route=args.route, duration=args.duration)
    if args.json:
        print_json(res)
        return 0
    rows = [(k, res["calls"].get(k, 0), res["stages_ms"][k], res["stages_ms_per_sim_s"][k]) for k in res["stages_ms"]]
    rows.append(("total", "", "", round(sum(res["stages_ms_per_sim_s"].values()), 2)))
    table(["stage", "calls", "ms / call", "ms / sim s"], rows,
          title=f"Loop: {res['sim_time_s']} sim s in {res['wall_s']} s wall, render {res['render_size'][0]}×{res['render_size'][1]}"
                f" with {res['renderer_note']}, detector {res['detector']}, stages {'in parallel' if res['parallel_stages'] else 'sequential'}")
    print(f"\nreal-time factor: ×{res['real_time_factor']}  (target ≥ ×10 with LIDAR and camera at 5 Hz)")
    if args.record:
        print(f"recording a rosbag2 bag ({res['bag_mb']} MB): ×{res['real_time_factor']} against "
              f"×{res['real_time_factor_without_recording']} without, a cost of {res['recording_cost_pct']} % "
              "(target ≤ 5 %; one pair of runs, so machine noise counts)")
    return 0
