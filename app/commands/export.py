"""Export maps, objects, trajectories, configs, recordings and whole sessions (the GUI buttons' CLI twins).

Examples:
    ocslam export map runs/tour --out maps/apartment.yaml       # map_server / Nav2 YAML + PGM
    ocslam export objects runs/tour --out objects.json [--all]  # vision_msgs Detection3D fields
    ocslam export trajectory runs/tour --out slam.tum
    ocslam export config --set consciousness.mode=seed --out seed.yaml
    ocslam export recording runs/tour --out tour.viser          # + tour.html, playable offline
    ocslam export session --route tour --duration 300 --out runs/tour   # = ocslam run --headless
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from app.config import ConfigError, atomic_write_text


def add_arguments(p: argparse.ArgumentParser) -> None:
    from app.commands.run import add_config_arguments

    sub = p.add_subparsers(dest="what", metavar="WHAT", required=True)
    for name, help_text in (
        ("map", "the session's occupancy grid as map_server YAML + PGM"),
        ("objects", "the session's object map (objects.json)"),
        ("trajectory", "the session's SLAM trajectory (TUM)"),
        ("recording", "a .viser recording (+ .html player) of the session"),
    ):
        q = sub.add_parser(name, help=help_text)
        q.add_argument("session", type=Path, help="run directory written by a headless run or 'Save session'")
        q.add_argument("--out", type=Path, required=True)
        if name == "objects":
            q.add_argument("--all", action="store_true", help="include objects below the presence threshold")
    q = sub.add_parser("config", help="a full config YAML (defaults + --config + --set)")
    add_config_arguments(q)
    q.add_argument("--out", type=Path, required=True)
    q = sub.add_parser("session", help="run headless and write a whole run directory")
    add_config_arguments(q)
    q.add_argument("--route", default=None)
    q.add_argument("--explore", action="store_true")
    q.add_argument("--duration", type=float, default=None)
    q.add_argument("--out", type=Path, required=True)


def run(args: argparse.Namespace) -> int:
    what = args.what
    if what == "config":
        from app.commands.run import config_from_args
        from app.session import check_out_file

        cfg = config_from_args(args)
        out = cfg.save(check_out_file(args.out))
        print(f"wrote {out}")
        return 0
    if what == "session":
        from app.commands.run import check_duration, config_from_args, run_headless

        check_duration(args.duration)
        return run_headless(config_from_args(args), route=args.route, explore=args.explore, duration=args.duration,
                            out=args.out)
    from app.session import check_out_file
    from app.session_load import read_session

    session: Path = args.session
    data = read_session(session).check()  # SessionError for a missing/corrupt session or a missing config.yaml
    cfg, state = data.cfg, data.state
    if what == "map":
        from app.ocslam.mapio import save_map

        out = check_out_file(args.out)
        if out.suffix.lower() == ".pgm":
            raise ConfigError(f"--out {args.out}: give the map's YAML file (its PGM is written beside it)")
        grid = data.slam().occupancy_grid()
        if not (grid.width and grid.height):
            raise ConfigError(f"{session}: the session's map is empty (no keyframes)")
        out = save_map(grid, out)
        print(f"wrote {out} and its PGM ({grid.width}×{grid.height} cells at {grid.resolution} m)")
        return 0
    if what == "trajectory":
        from app.session import tum_lines

        out = check_out_file(args.out)
        stamps, poses = data.slam().trajectory()
        atomic_write_text(out, tum_lines(stamps, poses))
        print(f"wrote {args.out} ({len(stamps)} poses)")
        return 0
    if what == "objects":
        from app.session import _finite_or_none, object_to_detection3d

        out = check_out_file(args.out)
        objects = data.consciousness().objects
        thr = cfg.consciousness.presence_threshold
        frame = "map"
        dets = [object_to_detection3d(o, float(state.get("sim_time", 0.0)), o.frame_id or frame)
                for o in objects if args.all or o.presence >= thr]
        doc = {"frame_id": frame, "presence_threshold": thr, "detections": dets}
        atomic_write_text(out, json.dumps(_finite_or_none(doc), indent=2, allow_nan=False))
        print(f"wrote {args.out} ({len(dets)} objects)")
        return 0
    if what == "recording":
        from app.config import atomic_write_bytes
        from app.pipeline import Pipeline
        from app.session import recording_bytes, recording_html
        from app.session_load import load_session

        out = check_out_file(args.out)
        html = out.with_suffix(".html")
        if html == out:
            raise ConfigError(f"--out {args.out}: name the .viser file; the .html player is written beside it")
        check_out_file(html, what="the player")
        cfg.set("detector.kind", "none")
        pipe = Pipeline(cfg)
        try:
            load_session(pipe, session)
            scene = recording_bytes(pipe)
        finally:
            pipe.close()
        # exactly these two names, each written atomically beside itself: nothing else is replaced
        atomic_write_bytes(out, scene)
        atomic_write_text(html, recording_html(scene))
        print(f"wrote {args.out} and {html.name}")
        return 0
    raise SystemExit(f"unknown export {what!r}")
