"""``ocslam bench all`` (``make bench``): every benchmark with its default arguments, one after another."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

from app.config import PROJECT_ROOT

DATASETS = PROJECT_ROOT.parent / "shared" / "datasets"


def commands(quick: bool) -> list[list[str]]:
    cmds = [["sim"], ["loop"] + (["--duration", "60"] if quick else []), ["ui"] + (["--seconds", "5"] if quick else [])]
    for name in ("intel", "aces"):
        if (DATASETS / name).is_dir():
            cmds.append(["slam", str(DATASETS / name)])
    cmds.append(["detector"] + (["--worlds", "2"] if quick else []))
    for mode in ("seed", "improved"):
        for det in ("oracle", "yolo"):
            cmds.append(["objects", "--mode", mode, "--detector", det])
    cmds.append(["objects", "--worlds", "3" if quick else "10", "--detector", "yolo"])
    if not quick:  # the world zoo (dev: tuned on; test: only reported) and the random layout families
        for suite in ("zoo-dev", "zoo-test", "random"):
            for det in ("oracle", "yolo"):
                cmds.append(["objects", "--suite", suite, "--detector", det])
        cmds.append(["slam", "--suite", "synthetic"])
    cmds.append(["loop", "--record"] + (["--duration", "30"] if quick else []))
    return cmds


def run(args: argparse.Namespace) -> int:
    failed = 0
    for cmd in commands(args.quick):
        full = [sys.executable, "-m", "app", "bench", *cmd] + (["--json"] if args.json else [])
        print(f"\n$ ocslam bench {' '.join(cmd)}", flush=True)
        r = subprocess.run(full, cwd=Path.cwd())
        failed += r.returncode != 0
    return 1 if failed else 0
