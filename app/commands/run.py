"""Run the simulation: the live web app (default) or ``--headless`` as fast as it can.

Examples:
    ocslam run                                   # web app on http://127.0.0.1:8080
    ocslam run --headless --route tour --duration 300 --out runs/tour
    ocslam run --headless --explore --world assets/worlds/small.yaml --out runs/explore
    ocslam run --config runs/tour/config.yaml --set consciousness.mode=seed
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
import time
from pathlib import Path

from app.config import Config, ConfigError


def add_config_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", type=Path, help="YAML config (e.g. one saved from the GUI or a run directory)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override one config value (repeatable)")
    p.add_argument("--world", help="world file (docs/world-format.md); default: the paper's apartment")
    p.add_argument("--detector", choices=("yolo", "oracle", "none"), help="detector kind")
    p.add_argument("--mode", choices=("improved", "seed"), help="consciousness mode")
    p.add_argument("--seed", type=int, help="random seed of sensor noise")


def config_from_args(args: argparse.Namespace) -> Config:
    overrides = list(args.overrides or [])
    if getattr(args, "world", None):
        overrides.append(f"sim.world={args.world}")
    if getattr(args, "detector", None):
        overrides.append(f"detector.kind={args.detector}")
    if getattr(args, "mode", None):
        overrides.append(f"consciousness.mode={args.mode}")
    if getattr(args, "seed", None) is not None:
        overrides.append(f"sim.seed={args.seed}")
    if getattr(args, "route", None):
        overrides.append(f"sim.route={args.route}")
    return Config.load(args.config, overrides)


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_config_arguments(p)
    p.add_argument("--headless", action="store_true", help="no browser: run as fast as possible and write a summary")
    p.add_argument("--route", help="headless: follow this named route of the world (default: sim.route)")
    p.add_argument("--explore", action="store_true", help="headless: frontier exploration instead of a route")
    p.add_argument("--duration", type=float, default=None, help="headless: stop after this many sim seconds")
    p.add_argument("--out", type=Path, help="headless: run directory for config.yaml, summary.json, map, objects")
    p.add_argument("--host", default=None, help="bind address (default 127.0.0.1; 0.0.0.0 exposes the robot)")
    p.add_argument("--port", type=int, default=None, help="port (default 8080; 0 = any free port)")
    p.add_argument("--no-token", action="store_true",
                   help="with a non-loopback --host: no access token (anyone who can reach the port drives the robot)")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.add_argument("--record", nargs="?", const="", default=None, metavar="BAG",
                   help="record a rosbag2 MCAP bag folder (headless default: <out>/bag; web app default: "
                        "runs/recording-<date>; or the Session panel's Record toggle); docs/ros2.md")


def check_duration(duration: float | None, what: str = "--duration") -> float | None:
    """``None`` or a positive finite number of sim seconds; :class:`ConfigError` otherwise."""
    if duration is None:
        return None
    if isinstance(duration, bool) or not isinstance(duration, (int, float)) or not math.isfinite(duration) or duration <= 0:
        raise ConfigError(f"{what} must be a positive number of sim seconds, got {duration!r}")
    return float(duration)


def run(args: argparse.Namespace) -> int:
    check_duration(args.duration)
    cfg = config_from_args(args)
    if args.host is not None:
        cfg.set("server.host", args.host)
    if args.port is not None:
        cfg.set("server.port", args.port)
    if getattr(args, "no_token", False):
        cfg.set("server.require_token", False)
    if args.headless:
        return run_headless(cfg, route=args.route, explore=args.explore, duration=args.duration, out=args.out,
                            quiet=args.quiet, record=args.record)
    from app.server import serve

    return serve(cfg, record=args.record)


def run_headless(
    cfg: Config,
    *,
    route: str | None = None,
    explore: bool = False,
    duration: float | None = None,
    out: Path | None = None,
    quiet: bool = False,
    record: str | None = None,
) -> int:
    """Drive the route (or explore) with no browser; write the run directory ``out`` as a unit at the end.

    Nothing in ``out`` is touched before the world, the route and the config have loaded: ``out`` is only
    checked (:func:`app.session.check_run_dir`), and written by :func:`app.session.save_session`.
    ``summary["end_reason"]`` is ``"duration"`` when ``duration`` stopped the run, ``"interrupted"``
    after Ctrl-C, otherwise the navigation status (route done, exploration done)."""
    from app.config import resolve_path
    from app.pipeline import Pipeline
    from app.session import check_run_dir, save_session
    from app.world.format import load_world

    duration = check_duration(duration)
    out = check_run_dir(out or Path("runs") / time.strftime("run-%Y%m%d-%H%M%S"))
    world = load_world(resolve_path(cfg.sim.world))
    if not explore:
        world.route(route or cfg.sim.route)  # WorldError naming the routes the world has
    pipe = Pipeline(cfg, world=world)
    try:
        if pipe.detector_error and cfg.detector.kind != "none":
            print(f"ocslam: warning: {pipe.detector_error}", file=sys.stderr)
        if explore:
            pipe.explore()
        else:
            pipe.follow_route(route or cfg.sim.route)
    except BaseException:
        pipe.close()
        raise
    limit = duration if duration is not None else (1800.0 if explore else 1200.0)
    rec = None
    if record is not None:  # a rosbag2 MCAP bag of the run (app/ros2/recorder.py)
        from app.ros2.recorder import attach, staging_path

        rec = attach(pipe, Path(record) if record else staging_path(out))

    interrupted = {"flag": False}

    def on_sigint(signum, frame):  # first Ctrl-C: finish cleanly and still write the summary
        interrupted["flag"] = True

    old = signal.signal(signal.SIGINT, on_sigint)
    bar = None
    if not quiet:
        try:
            from tqdm import tqdm

            bar = tqdm(total=round(limit), unit="sim s", file=sys.stderr, leave=False)
        except ImportError:
            bar = None
    pipe.wall_start = time.perf_counter()
    last_shown = 0.0
    timed_out = False
    try:
        while not interrupted["flag"]:
            if pipe.time >= limit - 1e-9:
                timed_out = True
                break
            pipe.step()
            if pipe.drive_mode == "idle" and pipe.nav_status:
                break  # route done / exploration done / stopped
            if explore and pipe.time - (pipe.coverage_log[-1][0] if pipe.coverage_log else -99.0) >= 5.0:
                pipe.sample_coverage()
            if bar is not None and pipe.time - last_shown >= 1.0:
                bar.update(round(pipe.time - last_shown))
                last_shown = round(pipe.time)
                bar.set_postfix_str(pipe.nav_status[:40])
    finally:  # our SIGINT handler stays until the run directory is written: a Ctrl-C now must not lose it
        stopped_by_user = interrupted["flag"]
        if bar is not None:
            bar.close()
        pipe.wall_time_s = time.perf_counter() - pipe.wall_start
        if rec is not None:
            from app.ros2.recorder import detach

            detach(pipe, rec)
        try:
            summary = pipe.summary()
            summary["end_reason"] = (
                "interrupted" if stopped_by_user else "duration" if timed_out else (pipe.nav_status or "stopped")
            )
            summary["duration_limit_s"] = limit
            if explore:
                summary.update(pipe.coverage_summary())
            extra = None
            if rec is not None and not record:
                from app.ros2.recorder import move_into_run_dir

                def extra(d: Path) -> None:  # the staged bag goes into the unit before it is renamed into place
                    move_into_run_dir(rec, d)

            save_session(pipe, out, summary=summary, extra=extra)
        finally:
            signal.signal(signal.SIGINT, old)
            pipe.close()
    if not quiet:
        keys = ("sim_time_s", "wall_time_s", "real_time_factor", "distance_m", "odom_final_error_m",
                "slam_ate_rmse_m", "map_precision", "map_recall", "objects_recall", "objects_precision_strict",
                "objects_pos_err_mean_m", "coverage", "end_reason")
        for k in keys:
            if k in summary:
                print(f"{k:>28}: {summary[k]}")
        print(f"{'run directory':>28}: {out}")
    return 130 if stopped_by_user else 0
