"""World files: write a randomized apartment, validate a file, or list the model catalogue.

Examples:
    ocslam world random --seed 7 --out worlds/random_7.yaml
    ocslam world random --family corridor --seed 7 --out worlds/corridor_7.yaml
    ocslam world validate assets/worlds/apartment.yaml
    ocslam world models
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="world_command", metavar="ACTION")
    r = sub.add_parser("random", help="write a randomized apartment (all 11 classes, a 'tour' route)")
    r.add_argument("--seed", type=int, required=True, help="random seed (the same seed gives the same world)")
    r.add_argument("--out", type=Path, required=True, help="output YAML file")
    r.add_argument("--rooms", type=int, default=None, help="number of rooms (default: 3–5 at random)")
    r.add_argument("--family", choices=("rooms", "corridor", "lshape", "openplan"), default="rooms",
                   help="layout family: rooms (a rectangle split into rooms), corridor (+ offices), lshape (an L-shaped "
                        "flat), openplan (app/world/layouts.py)")
    v = sub.add_parser("validate", help="load and check a world file (exit 2 with the offending entry)")
    v.add_argument("file", type=Path, nargs="+")
    sub.add_parser("models", help="list the model catalogue (name, class, size, legged)")


def run(args: argparse.Namespace) -> int:
    from app.world.format import dump_world, load_world
    from app.world.generator import random_world
    from app.world.types import WorldError, class_counts

    cmd = getattr(args, "world_command", None)
    if cmd == "random":
        from app.session import check_out_file

        check_out_file(args.out)  # before the (seconds-long) generation
        if getattr(args, "family", "rooms") != "rooms":
            from app.world.generator import generate

            world = generate(args.family, args.seed)
        else:
            world = random_world(args.seed, n_rooms=args.rooms)
        dump_world(world, args.out)
        counts = class_counts(world)
        print(
            f"wrote {args.out}: {world.description}; {len(world.objects)} objects "
            f"({', '.join(f'{k} {v}' for k, v in counts.items())}), {len(world.obstacles)} obstacles, "
            f"route 'tour' with {len(world.routes['tour'])} waypoints"
        )
        return 0
    if cmd == "validate":
        bad = 0
        for f in args.file:
            try:
                world = load_world(f)
            except WorldError as e:
                print(f"{e}", file=sys.stderr)
                bad += 1
                continue
            counts = {k: v for k, v in class_counts(world).items() if v}
            missing = [k for k, v in class_counts(world).items() if not v]
            print(
                f"{f}: OK — {len(world.walls)} walls, {len(world.obstacles)} obstacles, {len(world.objects)} objects "
                f"({', '.join(f'{k} {v}' for k, v in counts.items())}"
                + (f"; no {', '.join(missing)}" if missing else "")
                + f"), routes: {', '.join(f'{n} ({len(p)} pts)' for n, p in world.routes.items()) or 'none'}"
            )
        return 2 if bad else 0
    if cmd == "models":
        from app.bench.common import table
        from app.world.models.geometry import describe

        rows = [(r["model"], r["class"], "yes" if r["legged"] else "", " × ".join(f"{v:.2f}" for v in r["size_m"]), r["description"])
                for r in describe()]
        table(["model", "class", "legged", "size x × y × z (m)", "description"], rows)
        return 0
    print("usage: ocslam world {random,validate,models} ... (see ocslam world --help)", file=sys.stderr)
    return 2
