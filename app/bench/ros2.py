"""ROS 2 bags: what recording costs the loop, and how closely a replay reproduces the recorded run.

    ocslam bench ros2 --duration 60                 # record the tour, replay it (reuse / detector / SLAM trace)
    ocslam bench ros2 --duration 60 --ab 2          # + the loop's RTF without recording (alternating runs)
    ocslam bench ros2 --set replay.record_image_format=png

Figures: the live run's real-time factor with the recorder (and without, ``--ab``), the recorder's own
time on the loop thread, the bag's size; per replay mode its wall time and the largest trajectory and
object-centre differences against the live run (objects matched one-to-one by label).
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

from app.bench.common import print_json, table


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--duration", type=float, default=60.0, help="sim seconds of the tour to record")
    p.add_argument("--ab", type=int, default=0, metavar="N", help="also N runs without recording (alternating)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE")
    p.add_argument("--keep", type=Path, default=None, help="keep the bag here")


def _live(cfg: Any, duration: float, bag: Path | None) -> dict[str, Any]:
    from app.pipeline import Pipeline
    from app.ros2.recorder import attach, detach

    pipe = Pipeline(cfg)
    pipe.follow_route(cfg.sim.route)
    rec = attach(pipe, bag) if bag is not None else None
    t0 = time.perf_counter()
    while pipe.time < duration - 1e-9:
        pipe.step()
    if rec is not None:
        detach(pipe, rec)
    else:
        getattr(pipe, "wait_stages", lambda: None)()
    wall = time.perf_counter() - t0
    out = {"rtf": duration / wall, "wall_s": wall, "pipe": pipe, "recorder_s": rec.wall_s if rec else 0.0}
    return out


def run(args: argparse.Namespace) -> int:
    from app.config import Config
    from app.ros2.compare import object_map_difference, trajectory_difference
    from app.ros2.reader import read_bag
    from app.ros2.replay import ReplayCore
    from app.ros2.slam_trace import TraceReplay, attach_recorder, load_trace, save_trace, trace_from_core

    cfg = Config.load(None, args.overrides)
    tmp = Path(tempfile.mkdtemp(prefix="ocslam-bench-ros2-"))
    bag = tmp / "bag"
    try:
        on, off = [], []
        live = None
        for i in range(max(args.ab, 0) + 1):
            order = ("on", "off") if i % 2 == 0 else ("off", "on")
            for kind in order:
                if kind == "off" and i >= args.ab:
                    continue
                if kind == "on" and live is not None:
                    shutil.rmtree(bag, ignore_errors=True)
                r = _live(cfg, args.duration, bag if kind == "on" else None)
                (on if kind == "on" else off).append(r["rtf"])
                if kind == "on":
                    if live is not None:
                        live["pipe"].close()
                    live = r
                else:
                    r["pipe"].close()
        pipe = live["pipe"]
        live_traj = pipe.slam.trajectory()
        live_objs = pipe.objects_in_map()
        thr = cfg.consciousness.presence_threshold
        size = sum(f.stat().st_size for f in bag.iterdir())
        rows: dict[str, Any] = {}
        for reuse in (True, False):
            t0 = time.perf_counter()
            core = ReplayCore(cfg, read_bag(bag, with_images=not reuse), reuse_detections=reuse)
            core.keep_snapshots = False  # as headless replay
            rec = attach_recorder(core) if reuse else None
            core.run()
            wall = time.perf_counter() - t0
            if rec is not None:
                save_trace(trace_from_core(core, rec, "bench"), tmp / "trace.pkl")
            td = trajectory_difference(*live_traj, *core.slam.trajectory())
            od = object_map_difference(live_objs, core.objects_in_map(), thr)
            rows["reuse-detections" if reuse else "detector re-run"] = {
                "wall_s": round(wall, 2), "core_s": round(core.wall_s, 2),
                "stages_s": {k: round(v, 2) for k, v in core.timer.items()},
                "trajectory_max_m": td["max_m"], "trajectory_matched": f"{td['matched']}/{td['of']}",
                "objects_live": od["a"], "objects_replay": od["b"], "objects_matched": od["matched"],
                "object_max_m": od["max_m"],
            }
        # the next --reuse-detections replay of the same bag and SLAM settings: the SLAM trace (loaded from disk)
        t0 = time.perf_counter()
        traced = TraceReplay(load_trace(tmp / "trace.pkl"), cfg)
        traced.run()
        wall = time.perf_counter() - t0
        td = trajectory_difference(*live_traj, *traced.slam.trajectory())
        od = object_map_difference(live_objs, traced.objects_in_map(), thr)
        rows["reuse-detections, SLAM trace"] = {
            "wall_s": round(wall, 2), "core_s": round(traced.wall_s, 2), "stages_s": {"consciousness": round(traced.wall_s, 2)},
            "trajectory_max_m": td["max_m"], "trajectory_matched": f"{td['matched']}/{td['of']}",
            "objects_live": od["a"], "objects_replay": od["b"], "objects_matched": od["matched"], "object_max_m": od["max_m"],
        }
        pipe.close()
        result = {
            "duration_s": args.duration, "image_format": cfg.replay.record_image_format,
            "rtf_recording": round(sum(on) / len(on), 3),
            "rtf_without": round(sum(off) / len(off), 3) if off else None,
            "recording_cost_pct": round(100 * (1 - (sum(on) / len(on)) / (sum(off) / len(off))), 1) if off else None,
            "recorder_loop_thread_s": round(live["recorder_s"], 2), "live_wall_s": round(live["wall_s"], 1),
            "bag_mb": round(size / 1e6, 2), "replays": rows,
        }
        if args.keep is not None:
            shutil.copytree(bag, args.keep)
        if getattr(args, "json", False):
            print_json(result)
            return 0
        table(["figure", "value"], [
            ["sim seconds recorded", f"{args.duration:g}"],
            ["RTF with recording", result["rtf_recording"]],
            ["RTF without (A/B)", result["rtf_without"] if off else "–"],
            ["recording cost", f"{result['recording_cost_pct']} %" if off else "–"],
            ["recorder on the loop thread", f"{result['recorder_loop_thread_s']} s of {result['live_wall_s']} s"],
            ["bag size", f"{result['bag_mb']} MB ({result['image_format']})"],
        ], "recording")
        table(["replay", "wall s", "trajectory max m", "objects live/replay/matched", "object max m"], [
            [k, v["wall_s"], f"{v['trajectory_max_m']:.2e}", f"{v['objects_live']}/{v['objects_replay']}/{v['objects_matched']}",
             f"{v['object_max_m']:.2e}"] for k, v in rows.items()], "replay vs the live run")
        return 0
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
