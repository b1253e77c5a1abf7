"""``ocslam bench soak``: the headless loop for hours of sim time, exploring random worlds with YOLO on.

    ocslam bench soak --sim-hours 2 [--world-minutes 10] [--max-wall-minutes 90] [--warm-worlds 1] [--out soak.json] [--json]

One :class:`~app.pipeline.Pipeline` per world (``random_world(seed)``, seeds from ``--seed``), frontier
exploration until no frontier is left or ``--world-minutes`` of sim time have passed, then the next
world, until ``--sim-hours`` of sim time in all. Reported:

* **exceptions** (goal 0): uncaught exceptions out of ``Pipeline.step`` (the world is then abandoned)
  plus the errors the loop caught and counted itself (``counters.errors``: detector, SLAM, render…);
* **RSS** of this process alone ("main") and with its children (the render worker) in MiB, sampled every
  ``--sample-every`` sim s and ``--warmup`` sim s into every world. "Start" is the warm state: that sample
  in world ``--warm-worlds`` (default 1, i.e. after one whole world: the first world loads the model and
  the catalogue's meshes, and once its pipeline is freed glibc serves later large blocks from its heap,
  a one-time step that then plateaus; docs/benchmarks.md, "Soak"); growth = the last world's sample /
  start − 1 (goal < 10 %); the raw growth from world 0's sample is reported beside it;
* the **floor** each world leaves behind: RSS once its pipeline is closed and collected, then after glibc's
  ``malloc_trim(0)`` (``--no-trim``: not called); it grows from world to world only with a leak;
* per world: tracked objects against the objects in the world, keyframes, the frame-skip counters,
  real-time factor.

``--out FILE`` is rewritten after every world and every minute within one (the world in progress marked
``"partial"``), so a run that is stopped still leaves its figures.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from app.bench.common import print_json, table
from app.commands.run import add_config_arguments, config_from_args
from app.memory import malloc_trim


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_config_arguments(p)
    p.add_argument("--sim-hours", type=float, default=2.0, help="total sim time")
    p.add_argument("--world-minutes", type=float, default=10.0, help="sim minutes per world at most")
    p.add_argument("--warmup", type=float, default=60.0, help="sim seconds into each world where RSS is sampled")
    p.add_argument("--warm-worlds", type=int, default=1,
                   help="RSS start = the --warmup sample of this world (0-based; 1: after one whole world)")
    p.add_argument("--sample-every", type=float, default=30.0, help="sim seconds between RSS samples")
    p.add_argument("--no-trim", action="store_true",
                   help="no malloc_trim(0) after each world (the floor a world leaves behind is not measured)")
    p.add_argument("--seed0", type=int, default=99100, help="first random_world seed")
    p.add_argument("--max-wall-minutes", type=float, default=None, help="stop (and say so) after this much wall time")
    p.add_argument("--out", type=Path, default=None, help="write the JSON result here after every world")
    p.add_argument("--json", action="store_true")


def rss_mib(pid: int | None = None, *, children: bool = True) -> float:
    """Resident set size of ``pid`` (default: this process) plus all its descendants (unless
    ``children=False``), MiB (Linux /proc)."""
    pid = os.getpid() if pid is None else pid
    total = 0
    stack, seen = [pid], set()
    while stack:
        p = stack.pop()
        if p in seen:
            continue
        seen.add(p)
        try:
            for line in Path(f"/proc/{p}/status").read_text().splitlines():
                if line.startswith("VmRSS:"):
                    total += int(line.split()[1]) * 1024
                    break
            if not children:
                break
            for task in Path(f"/proc/{p}/task").iterdir():
                kids = (task / "children").read_text().split()
                stack.extend(int(k) for k in kids)
        except (OSError, ValueError):
            continue
    return total / 2**20


def _sum(d: dict[str, int]) -> int:
    return int(sum(int(v) for v in d.values()))


def soak_world(cfg, seed: int, *, sim_budget_s: float, warmup_s: float, deadline: float | None,
               sample_every_s: float = 30.0, progress: Callable[[dict[str, Any]], None] | None = None,
               progress_every_wall_s: float = 60.0, trim: bool = True) -> dict[str, Any]:
    """Explore ``random_world(seed)`` for at most ``sim_budget_s``; the world's figures.

    ``rss_samples``: ``[sim s in this world, MiB of this process, MiB with its children]`` every
    ``sample_every_s`` of sim time; ``progress(res)`` gets the world's record so far (``"partial": True``)
    every ``progress_every_wall_s`` of wall time, so a stopped run still has the world's samples."""
    from app.pipeline import Pipeline
    from app.world.generator import random_world

    world = random_world(seed)
    t0 = time.perf_counter()
    pipe = Pipeline(cfg, world=world)
    res: dict[str, Any] = {"seed": seed, "world_objects": len(world.objects), "exceptions": 0, "exception_messages": [],
                           "rss_samples": [], "partial": True}
    try:
        if pipe.detector_error and cfg.detector.kind != "none":
            raise RuntimeError(pipe.detector_error)
        pipe.explore()
        rss_warm = rss_warm_main = None
        end = "world time budget"
        next_sample, next_progress = 0.0, t0 + progress_every_wall_s
        while pipe.time < sim_budget_s:
            try:
                pipe.step()
            except Exception as e:  # counted, and the world is abandoned: its state is not to be trusted
                res["exceptions"] += 1
                res["exception_messages"].append(f"{type(e).__name__}: {e}"[:300])
                end = "exception"
                break
            if rss_warm is None and pipe.time >= warmup_s:
                rss_warm = rss_mib()
                rss_warm_main = rss_mib(children=False)
            if pipe.time >= next_sample:
                res["rss_samples"].append([round(pipe.time, 1), round(rss_mib(children=False), 1), round(rss_mib(), 1)])
                next_sample += sample_every_s
            if progress is not None and time.perf_counter() >= next_progress:
                res["sim_s"] = round(pipe.time, 1)
                progress(res)
                next_progress = time.perf_counter() + progress_every_wall_s
            if pipe.drive_mode == "idle" and pipe.nav_status:
                end = pipe.nav_status
                break
            if deadline is not None and time.perf_counter() > deadline:
                end = "wall-time limit"
                break
        wall = time.perf_counter() - t0
        c = pipe.counters
        res.update({
            "sim_s": round(pipe.time, 1),
            "wall_s": round(wall, 1),
            "real_time_factor": round(pipe.time / wall, 2) if wall > 0 else None,
            "end": end,
            "rss_warm_mib": round(rss_warm, 1) if rss_warm is not None else None,
            "rss_end_mib": round(rss_mib(), 1),
            "rss_warm_main_mib": round(rss_warm_main, 1) if rss_warm_main is not None else None,
            "rss_end_main_mib": round(rss_mib(children=False), 1),
            "tracked_objects": len(pipe.consciousness.objects),
            "objects_in_map": len(pipe.objects_in_map()),
            "keyframes": len(pipe.slam.pose_graph().nodes),
            "scans": c.scans,
            "images": c.images,
            "detections": c.detections,
            "fused_frames": c.fused_frames,
            "skipped_frames": dict(c.skipped_frames),
            "slam_skipped": dict(getattr(pipe.slam, "skipped", {})),
            "loop_errors": dict(c.errors),
            "coverage": round(pipe.coverage(), 3),
        })
    finally:
        pipe.close()
    del pipe
    gc.collect()
    #: what this world left behind in the process: RSS once its pipeline is closed and collected, and
    #: once glibc has handed its free heap pages back (``trim``); the second one is the leak figure
    res["rss_closed_main_mib"] = round(rss_mib(children=False), 1)
    if trim and malloc_trim():
        res["rss_trimmed_main_mib"] = round(rss_mib(children=False), 1)
    res["partial"] = False
    return res


def soak(cfg, *, sim_hours: float, world_minutes: float, warmup_s: float, seed0: int,
         max_wall_minutes: float | None = None, out: Path | None = None, warm_worlds: int = 1,
         trim: bool = True, sample_every_s: float = 30.0) -> dict[str, Any]:
    t0 = time.perf_counter()
    deadline = t0 + 60.0 * max_wall_minutes if max_wall_minutes else None
    target = 3600.0 * sim_hours
    result: dict[str, Any] = {
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "sim_hours_target": sim_hours,
        "detector": cfg.detector.kind,
        "cores": os.cpu_count(),
        "load_average": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
        "warm_worlds": int(warm_worlds),
        "malloc_trim": bool(trim),
        "rss_process_start_mib": round(rss_mib(), 1),
        "worlds": [],
    }
    done_s, seed = 0.0, seed0

    def write(worlds: list[dict[str, Any]], sim_s: float) -> None:
        if out is None:
            return
        from app.config import atomic_write_text

        snapshot = {**result, "worlds": worlds}
        _summarise(snapshot, sim_s, time.perf_counter() - t0, target)
        atomic_write_text(out, json.dumps(snapshot, indent=2) + "\n")

    while done_s < target - 1e-6:
        if deadline is not None and time.perf_counter() > deadline:
            break
        budget = min(60.0 * world_minutes, target - done_s)
        base = done_s
        w = soak_world(cfg, seed, sim_budget_s=budget, warmup_s=min(warmup_s, budget), deadline=deadline,
                       trim=trim, sample_every_s=sample_every_s, progress=lambda part, base=base: write([*result["worlds"], part], base + part.get("sim_s", 0.0)))
        result["worlds"].append(w)
        done_s += w.get("sim_s", 0.0)
        seed += 1
        write(result["worlds"], done_s)
        if w.get("sim_s", 0.0) <= 0.0:
            break  # nothing advances: no point in looping forever
    _summarise(result, done_s, time.perf_counter() - t0, target)
    return result


def _growth(a: float | None, b: float | None) -> float | None:
    return round(100.0 * (b / a - 1.0), 2) if a and b is not None else None


def _summarise(result: dict[str, Any], done_s: float, wall_s: float, target: float) -> None:
    """The run's figures from its worlds. RSS "start" is the warm state: the sample ``--warmup`` sim s into
    world ``warm_worlds`` (0-based; default 1, i.e. after one whole world, whose first pipeline fills the
    one-time caches and raises glibc's mmap threshold); the raw first sample (world 0) is reported too."""
    ws = result["worlds"]
    k = int(result.get("warm_worlds", 1))

    def pick(key: str) -> list[float]:
        return [w[key] for w in ws if w.get(key) is not None]

    warm, main = pick("rss_warm_mib"), pick("rss_warm_main_mib")
    start = warm[k] if len(warm) > k else None
    start_main = main[k] if len(main) > k else None
    last, last_main = (warm[-1] if warm else None), (main[-1] if main else None)
    trimmed = pick("rss_trimmed_main_mib")
    result.update({
        "sim_s": round(done_s, 1),
        "sim_hours": round(done_s / 3600.0, 3),
        "wall_s": round(wall_s, 1),
        "real_time_factor": round(done_s / wall_s, 2) if wall_s > 0 else None,
        "complete": done_s >= target - 1e-6,
        "worlds_done": sum(not w.get("partial") for w in ws),
        "exceptions": sum(w["exceptions"] for w in ws),
        "loop_errors": sum(_sum(w.get("loop_errors", {})) for w in ws),
        # with the render worker
        "rss_start_mib": start,
        "rss_last_warm_mib": last,
        "rss_growth_pct": _growth(start, last) if len(warm) > k + 1 else None,
        "rss_end_mib": ws[-1].get("rss_end_mib") if ws else None,
        "rss_max_mib": max((s[2] for w in ws for s in w.get("rss_samples", [])), default=None),
        "rss_first_sample_mib": warm[0] if warm else None,
        "rss_growth_raw_pct": _growth(warm[0], last) if len(warm) >= 2 else None,
        # the loop process alone
        "rss_main_start_mib": start_main,
        "rss_main_last_warm_mib": last_main,
        "rss_main_growth_pct": _growth(start_main, last_main) if len(main) > k + 1 else None,
        "rss_main_end_mib": ws[-1].get("rss_end_main_mib") if ws else None,
        "rss_main_max_mib": max((s[1] for w in ws for s in w.get("rss_samples", [])), default=None),
        "rss_main_first_sample_mib": main[0] if main else None,
        "rss_main_growth_raw_pct": _growth(main[0], last_main) if len(main) >= 2 else None,
        # what the worlds left behind (pipeline closed, heap trimmed): grows per world only with a leak
        "rss_main_floor_mib": trimmed,
        "rss_main_floor_growth_pct": _growth(trimmed[k], trimmed[-1]) if len(trimmed) > k + 1 else None,
        "skipped_frames": _merge([w.get("skipped_frames", {}) for w in ws]),
        "slam_skipped": _merge([w.get("slam_skipped", {}) for w in ws]),
    })


def _merge(ds: list[dict[str, int]]) -> dict[str, int]:
    out: dict[str, int] = {}
    for d in ds:
        for k, v in d.items():
            out[k] = out.get(k, 0) + int(v)
    return out


def run(args: argparse.Namespace) -> int:
    cfg = config_from_args(args)
    if args.detector is None and not any(o.startswith("detector.kind=") for o in args.overrides):
        cfg.set("detector.kind", "yolo")
    for name in ("sim_hours", "world_minutes"):
        v = getattr(args, name)
        if not (v == v and 0 < v < float("inf")):
            from app.config import ConfigError

            raise ConfigError(f"--{name.replace('_', '-')} must be a positive number, got {v}")
    if args.warm_worlds < 0:
        from app.config import ConfigError

        raise ConfigError(f"--warm-worlds must be 0 or more, got {args.warm_worlds}")
    if not (args.sample_every == args.sample_every and 0 < args.sample_every < float("inf")):
        from app.config import ConfigError

        raise ConfigError(f"--sample-every must be a positive number, got {args.sample_every}")
    res = soak(cfg, sim_hours=args.sim_hours, world_minutes=args.world_minutes, warmup_s=args.warmup,
               seed0=args.seed0, max_wall_minutes=args.max_wall_minutes, out=args.out, warm_worlds=args.warm_worlds,
               trim=not args.no_trim, sample_every_s=args.sample_every)
    if args.json:
        print_json(res)
        return 0 if res["exceptions"] == 0 else 1
    rows = [(w["seed"], w.get("sim_s"), w.get("real_time_factor"), w.get("end", "")[:28], w["exceptions"],
             _sum(w.get("loop_errors", {})), f"{w.get('tracked_objects')}/{w['world_objects']}", w.get("keyframes"),
             _sum(w.get("skipped_frames", {})), w.get("rss_warm_mib"), w.get("rss_end_mib")) for w in res["worlds"]]
    table(["seed", "sim s", "RTF", "end", "exc", "loop err", "objects/world", "keyframes", "skipped", "RSS warm MiB",
           "RSS end MiB"], rows, title=f"Soak: {res['sim_hours']} of {res['sim_hours_target']} sim h in {res['wall_s']} s wall")
    print(f"exceptions: {res['exceptions']} uncaught + {res['loop_errors']} caught (goal 0)")
    print(f"RSS of the loop process: {res['rss_main_start_mib']} MiB at the warm start (world {res['warm_worlds']}) → "
          f"{res['rss_main_last_warm_mib']} MiB at the same point of the last world ({res['rss_main_growth_pct']} %, "
          f"goal < 10 %); raw from the first sample {res['rss_main_first_sample_mib']} MiB: "
          f"{res['rss_main_growth_raw_pct']} %; {res['rss_main_end_mib']} MiB at the end, {res['rss_main_max_mib']} max")
    print(f"RSS with the render worker: {res['rss_start_mib']} → {res['rss_last_warm_mib']} MiB ({res['rss_growth_pct']} %); "
          f"raw {res['rss_first_sample_mib']} MiB: {res['rss_growth_raw_pct']} %")
    print(f"left behind by each world (closed, heap trimmed): {res['rss_main_floor_mib']} MiB "
          f"({res['rss_main_floor_growth_pct']} % from world {res['warm_worlds']})")
    print(f"frame skips: {res['skipped_frames']}; SLAM skips: {res['slam_skipped']}")
    if not res["complete"]:
        print("incomplete: stopped by --max-wall-minutes before --sim-hours of sim time")
    return 0 if res["exceptions"] == 0 else 1
