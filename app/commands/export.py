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

from app.config import Config, atomic_write_text


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


def _state(session: Path) -> dict:
    import numpy as np

    from app.session import unpack_state

    f = session / "state.npz"
    if not f.is_file():
        raise FileNotFoundError(f"{session} is not a session directory (no state.npz)")
    with np.load(f, allow_pickle=False) as z:
        return unpack_state({k: z[k] for k in z.files})


def _config(session: Path) -> Config:
    c = session / "config.yaml"
    return Config.load(c) if c.is_file() else Config()


def run(args: argparse.Namespace) -> int:
    what = args.what
    if what == "config":
        from app.commands.run import config_from_args

        out = config_from_args(args).save(args.out)
        print(f"wrote {out}")
        return 0
    if what == "session":
        from app.commands.run import config_from_args, run_headless

        return run_headless(config_from_args(args), route=args.route, explore=args.explore, duration=args.duration,
                            out=args.out)
    session: Path = args.session
    cfg = _config(session)
    state = _state(session)
    if what == "map":
        from app.ocslam.mapio import save_map
        from app.ocslam.slam import Slam

        grid = Slam.from_state_dict(cfg.slam, state["slam"]).occupancy_grid()
        out = save_map(grid, args.out)
        print(f"wrote {out} and its PGM ({grid.width}×{grid.height} cells at {grid.resolution} m)")
        return 0
    if what == "trajectory":
        from app.ocslam.slam import Slam
        from app.session import tum_lines

        stamps, poses = Slam.from_state_dict(cfg.slam, state["slam"]).trajectory()
        atomic_write_text(args.out, tum_lines(stamps, poses))
        print(f"wrote {args.out} ({len(stamps)} poses)")
        return 0
    if what == "objects":
        from app.ocslam.consciousness import Consciousness
        from app.pipeline import build_camera_model
        from app.robot_model import RobotModel
        from app.session import object_to_detection3d

        cons = Consciousness.from_state_dict(state["consciousness"], cfg.consciousness,
                                             build_camera_model(cfg, RobotModel.load()))
        objects = cons.objects
        thr = cfg.consciousness.presence_threshold
        frame = "map"
        dets = [object_to_detection3d(o, float(state.get("sim_time", 0.0)), o.frame_id or frame)
                for o in objects if args.all or o.presence >= thr]
        atomic_write_text(args.out, json.dumps({"frame_id": frame, "presence_threshold": thr, "detections": dets}, indent=2))
        print(f"wrote {args.out} ({len(dets)} objects)")
        return 0
    if what == "recording":
        from app.pipeline import Pipeline
        from app.session import load_session, write_recording

        cfg.set("detector.kind", "none")
        pipe = Pipeline(cfg)
        try:
            load_session(pipe, session)
            tmp = args.out.parent
            tmp.mkdir(parents=True, exist_ok=True)
            write_recording(pipe, tmp)
            (tmp / "scene.viser").replace(args.out)
            html = tmp / "scene.html"
            if html.exists():
                html.replace(args.out.with_suffix(".html"))
        finally:
            pipe.close()
        print(f"wrote {args.out}")
        return 0
    raise SystemExit(f"unknown export {what!r}")
