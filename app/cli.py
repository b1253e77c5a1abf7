"""The ``ocslam`` command line.

Each sub-command lives in its own module that defines ``add_arguments(parser)`` and
``run(args) -> int``; this file only lists them, so commands can be added without touching each
other. Every ``ocslam bench …`` command accepts ``--json``.

    ocslam run [--headless] [--world FILE] [--config FILE] [--set section.key=value ...]
    ocslam world random --seed N --out FILE
    ocslam dataset --worlds N --per-world M --seed S --out DIR
    ocslam train-detector --data DIR
    ocslam export map|objects|session ...
    ocslam bench sim|slam|detector|objects|ui|loop|all [--json]
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence
from typing import Any

#: name → (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "run": ("app.commands.run", "run the simulation (web app, or --headless)"),
    "world": ("app.commands.world", "world files: validate, random"),
    "dataset": ("app.commands.dataset", "render an auto-labelled YOLO dataset from the simulator"),
    "train-detector": ("app.commands.train_detector", "train the YOLO detector (needs the [train] extra)"),
    "export": ("app.commands.export", "export maps, objects and sessions"),
    "replay": ("app.commands.replay", "replay a ROS 1 / rosbag2 bag through the core (--headless, --reuse-detections)"),
    "sweep": ("app.commands.sweep", "tuning sweep over a suite of worlds on Ray Tune (needs the [scale] extra)"),
}

BENCHES: dict[str, tuple[str, str]] = {
    "sim": ("app.bench.sim", "simulator step, LIDAR and camera timings, headless real-time factor"),
    "slam": ("app.bench.slam", "SLAM on a CARMEN log against the Kümmerle et al. relations"),
    "detector": ("app.bench.detector", "detector precision/recall/mAP and latency on held-out renders"),
    "objects": ("app.bench.objects", "the object map against ground truth (the paper's results table)"),
    "ui": ("app.bench.ui", "server CPU and bytes per tick per client"),
    "loop": ("app.bench.loop", "the complete loop's per-stage time and real-time factor"),
    "ros2": ("app.bench.ros2", "ROS 2 bags: recording cost, replay time and reproduction of the live run"),
    "soak": ("app.bench.soak", "hours of headless exploration over random worlds: exceptions, RSS growth, counts"),
}


def _load(module: str):
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as e:
        if e.name and module.startswith(e.name):
            return None
        raise


class _Parser(argparse.ArgumentParser):
    """Usage errors as one ``ocslam: error: …`` line (exit 2), like every other CLI failure."""

    def error(self, message: str) -> None:  # type: ignore[override]
        print(f"ocslam: error: {self.prog}: {message} (see {self.prog} --help)", file=sys.stderr)
        raise SystemExit(2)


def _selected(argv: Sequence[str] | None) -> tuple[str | None, str | None] | None:
    """The ``(command, bench)`` that ``argv`` names, or None to load every command (``argv`` None).

    The top-level parser has no options but ``-h``, so the first word that is not an option is the
    command, and after ``bench`` the next one is the benchmark."""
    if argv is None:
        return None
    words = [a for a in argv if not a.startswith("-")]
    command = words[0] if words else None
    bench = words[1] if command == "bench" and len(words) > 1 else None
    return command, bench


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The ``ocslam`` parser. With ``argv``, only the sub-command it names imports its module (the
    others are listed by name and help), so ``ocslam replay …`` does not pay for importing every
    benchmark's dependencies; without, every command's arguments are built (tests, docs)."""
    chosen = _selected(argv)
    parser = _Parser(prog="ocslam", description="Object-Conscious SLAM in a simulated apartment.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    def add(parent: Any, name: str, module: str, help_text: str, wanted: bool, is_bench: bool = False) -> None:
        if not wanted:
            parent.add_parser(name, help=help_text)
            return
        mod = _load(module)
        if mod is None:
            return
        p = parent.add_parser(name, help=help_text, description=(mod.__doc__ or help_text).strip().splitlines()[0])
        mod.add_arguments(p)
        if is_bench and not any(a.dest == "json" for a in p._actions):
            p.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
        p.set_defaults(_run=mod.run)

    for name, (module, help_text) in COMMANDS.items():
        add(sub, name, module, help_text, chosen is None or chosen[0] == name)
    bench = sub.add_parser("bench", help="benchmarks (each prints a table, or JSON with --json)")
    bsub = bench.add_subparsers(dest="bench", metavar="BENCH")
    for name, (module, help_text) in BENCHES.items():
        add(bsub, name, module, help_text, chosen is None or chosen == ("bench", name), is_bench=True)
    pall = bsub.add_parser("all", help="run every benchmark with its default arguments")
    pall.add_argument("--json", action="store_true")
    pall.add_argument("--quick", action="store_true", help="shorter runs")
    pall.set_defaults(_run=_bench_all)
    return parser


def _bench_all(args: argparse.Namespace) -> int:
    mod = _load("app.bench.all")
    if mod is None:
        print("ocslam bench all: no benchmarks are installed", file=sys.stderr)
        return 2
    return int(mod.run(args))


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    if not hasattr(args, "_run"):
        parser.print_help()
        return 2
    try:
        return int(args._run(args) or 0)
    except KeyboardInterrupt:
        return 130
    except Exception as e:  # a clear one-line error, not a traceback, for user-facing failures
        from app.config import ConfigError

        known = (ConfigError, FileNotFoundError)
        try:
            from app.world.types import WorldError

            known = known + (WorldError,)
        except ImportError:
            pass
        try:
            from app.ocslam.detector import DetectorError

            known = known + (DetectorError,)
        except ImportError:
            pass
        try:
            from app.session import SessionError

            known = known + (SessionError,)
        except ImportError:
            pass
        if isinstance(e, known + (OSError,)):  # OSError: --out not writable, a file where a folder must be, …
            msg = str(e) if not isinstance(e, OSError) or not e.filename else f"{e.filename}: {e.strerror or e}"
            msg = " ".join(str(msg).split())  # one line, whatever the message (e.g. a YAML error's excerpt)
            print(f"ocslam: error: {msg}", file=sys.stderr)
            return 2
        if os.environ.get("OCSLAM_TRACEBACK"):
            raise
        # a bug, not a bad input: still one line (OCSLAM_TRACEBACK=1 shows where)
        print(f"ocslam: error: internal error: {type(e).__name__}: {e} (OCSLAM_TRACEBACK=1 for the traceback)",
              file=sys.stderr)
        return 2
