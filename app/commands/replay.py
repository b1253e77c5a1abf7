"""Replay a robot bag (ROS 1 .bag, rosbag2 sqlite3 or MCAP) through OCSLAM's core.

Examples:
    ocslam replay runs/tour/bag --headless --out runs/tour-replay     # detector re-run on the images
    ocslam replay runs/tour/bag --headless --reuse-detections           # consciousness on /yolo_boxes
    ocslam replay ../shared/datasets/hw2-bag/hw2_data.bag --headless \\
        --set 'replay.T_base_scan=[0.2,0,0,0,3.14159265,0]'             # upside-down LIDAR, no /tf_static
    ocslam replay runs/tour/bag                                         # web app with a timeline

Needs a scan topic and odometry (``/odom``, or ``/tf`` odom → base); with a camera topic and
``camera_info`` it runs the detector and the consciousness too. docs/ros2.md has the details.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from pathlib import Path

from app.commands.run import add_config_arguments, config_from_args


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("bag", type=Path, help="a ROS 1 .bag file or a rosbag2 folder (sqlite3 or MCAP)")
    add_config_arguments(p)
    p.add_argument("--headless", action="store_true", help="no browser: replay as fast as possible, write a run directory")
    p.add_argument("--rate", type=float, default=None,
                   help="playback rate (web app: start rate, 0.25-8; headless: pace at this many × bag time)")
    p.add_argument("--start", type=float, default=0.0, help="start this many seconds into the bag")
    p.add_argument("--topics", nargs="+", default=None, metavar="TOPIC",
                   help="read only these topics (plus /tf_static)")
    p.add_argument("--reuse-detections", action="store_true",
                   help="run the consciousness on the recorded /yolo_boxes instead of the detector on the images")
    p.add_argument("--slam-trace", choices=("auto", "off", "refresh"), default="auto",
                   help="headless --reuse-detections: keep the SLAM's side of the replay (poses, keyframes, grid, "
                        "corrections) in the cache and reuse it while the bag, the SLAM/replay settings and "
                        "consciousness.mode/sync_tolerance_s/corner_check are unchanged, so only the object map "
                        "re-runs (auto, default); off: always re-run the SLAM; refresh: re-run and store it")
    p.add_argument("--cache-dir", type=Path, default=None,
                   help="where SLAM traces are kept (default $OCSLAM_CACHE_DIR/replay; with neither, none is kept)")
    p.add_argument("--out", type=Path, help="headless: run directory (default runs/replay-<time>)")
    p.add_argument("--host", default=None, help="web app bind address (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=None, help="web app port (default 8080; 0 = any free port)")
    p.add_argument("--quiet", action="store_true", help="no progress output")


def open_replay(args: argparse.Namespace):
    """The config, the bag and a :class:`app.ros2.replay.ReplayCore` from the command line."""
    from app.ros2.errors import BagError
    from app.ros2.reader import BagTopics, read_bag
    from app.ros2.replay import ReplayCore

    cfg = config_from_args(args)
    if args.rate is not None and not (0.0 < args.rate <= 1000.0):
        raise BagError(f"--rate must be in (0, 1000], got {args.rate}")
    if not (args.start >= 0.0):
        raise BagError(f"--start must be ≥ 0 s, got {args.start}")
    r = cfg.replay
    names = BagTopics(scan=r.scan_topic, odom=r.odom_topic, image=r.image_topic, image_raw=r.image_raw_topic,
                      camera_info=r.camera_info_topic, yolo_boxes=r.yolo_boxes_topic)
    bag = read_bag(args.bag, names, with_images=not args.reuse_detections,
                   only=set(args.topics) if args.topics else None)
    if args.start > 0 and bag.events:
        t0 = bag.events[0].t + args.start
        bag.events = [e for e in bag.events if e.t >= t0]
        if not any(e.kind == "scan" for e in bag.events):
            raise BagError(f"{args.bag}: no scans after --start {args.start} s (the bag lasts {bag.duration_s:.1f} s)")
    core = ReplayCore(cfg, bag, reuse_detections=args.reuse_detections)
    return cfg, core


def _trace_path(args: argparse.Namespace):
    """``(key, path)`` of the SLAM trace this headless ``--reuse-detections`` replay may use, else None."""
    if not (args.headless and args.reuse_detections) or getattr(args, "slam_trace", "off") == "off" or args.rate:
        return None
    from app.ros2.slam_trace import default_cache_dir, trace_key

    cache = args.cache_dir or default_cache_dir()
    if cache is None:  # no cache chosen: nothing is kept, the SLAM re-runs
        return None
    cfg = config_from_args(args)
    key = trace_key(args.bag, cfg, args.start, args.topics)
    return key, cache / f"{key}.pkl"


def run(args: argparse.Namespace) -> int:
    from app.ros2.errors import BagError

    try:
        traced = _trace_path(args)
    except (OSError, ValueError) as e:  # the cache is an optimisation: never a reason to fail
        print(f"ocslam replay: warning: SLAM trace unavailable: {e}", file=sys.stderr)
        traced = None
    if traced is not None and args.slam_trace == "auto":
        from app.ros2.slam_trace import TraceReplay, load_trace

        trace = load_trace(traced[1])
        if trace is not None and trace.key == traced[0]:
            core = TraceReplay(trace, config_from_args(args))
            if not args.quiet:
                print(f"ocslam replay: SLAM from the trace {traced[1]} (consciousness only; --slam-trace off re-runs it)",
                      file=sys.stderr)
            return run_headless(core, out=args.out, quiet=args.quiet)
    try:
        cfg, core = open_replay(args)
    except BagError as e:
        print(f"ocslam replay: error: {e}", file=sys.stderr)
        return 2
    for w in core.warnings:
        print(f"ocslam replay: warning: {w}", file=sys.stderr)
    if args.headless:
        core.keep_snapshots = False  # nothing seeks
        rec = None
        if traced is not None and core.fusing:
            from app.ros2.slam_trace import attach_recorder

            rec = attach_recorder(core)
        rc = run_headless(core, out=args.out, rate=args.rate, quiet=args.quiet)
        if rec is not None and rc == 0:
            from app.ros2.slam_trace import save_trace, trace_from_core

            try:
                save_trace(trace_from_core(core, rec, traced[0]), traced[1])
            except OSError as e:
                print(f"ocslam replay: warning: SLAM trace not saved: {e}", file=sys.stderr)
        return rc
    if args.host is not None:
        cfg.set("server.host", args.host)
    if args.port is not None:
        cfg.set("server.port", args.port)
    from app.ui.replay import serve_replay

    return serve_replay(core, rate=args.rate or 1.0)


def run_headless(core, *, out: Path | None = None, rate: float | None = None, quiet: bool = False) -> int:
    """Replay the whole bag, write the run directory, print the summary (and the paper's table)."""
    from app.ros2.rundir import write_run_dir

    out = out or Path("runs") / time.strftime("replay-%Y%m%d-%H%M%S")
    interrupted = {"flag": False}

    def on_sigint(signum, frame):
        interrupted["flag"] = True

    old = signal.signal(signal.SIGINT, on_sigint)
    wall0 = time.perf_counter()
    bag_t0 = core.t_start
    try:
        while not interrupted["flag"]:
            e = core.step()
            if e is None:
                break
            if rate:
                ahead = (e.t - bag_t0) / rate - (time.perf_counter() - wall0)
                if ahead > 0:
                    time.sleep(ahead)
        stopped_by_user = interrupted["flag"]
        summary = core.summary()
        summary["end_reason"] = "interrupted" if stopped_by_user else "end of bag"
        write_run_dir(core, out, summary)  # still under our handler: a Ctrl-C while saving must not lose the run
    finally:
        signal.signal(signal.SIGINT, old)
    if not quiet:
        for k in ("bag_time_s", "wall_time_s", "real_time_factor", "lidar_extrinsic", "slam_ate_rmse_m",
                  "objects_recall", "objects_precision_strict", "objects_pos_err_mean_m", "end_reason"):
            if k in summary:
                print(f"{k:>28}: {summary[k]}")
        rep = core.object_report() if core.fusing else None
        if rep is not None:
            from app.ocslam.evaluation import PAPER_ROW, format_table

            print()
            print(format_table({"paper (seed, real robot)": PAPER_ROW, "replay": rep}))
        print(f"{'run directory':>28}: {out}")
    return 130 if stopped_by_user else 0
