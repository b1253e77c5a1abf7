"""``ocslam sweep SPEC.yaml``: a tuning sweep on Ray Tune over a suite of worlds (docs/tuning.md).

Examples:
    ocslam sweep assets/sweeps/six-constants.yaml                     # local Ray, 2 workers, runs/sweep-<name>
    ocslam sweep SPEC.yaml --workers 4 --out runs/my-sweep
    ocslam sweep SPEC.yaml --out runs/my-sweep --resume               # after Ctrl-C: finish the trials left
    RAY_ADDRESS=ray://head:10001 ocslam sweep SPEC.yaml               # an existing cluster (or --address)
    ocslam sweep SPEC.yaml --check                                    # validate the file only

Writes ``OUT/results.jsonl`` (a line per finished trial), ``results.csv``, ``results.md``, ``best.yaml``
(``ocslam run --config OUT/best.yaml``), ``plots/*.png`` and ``sweep.json``; Ray's state under ``OUT/tune``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("spec", type=Path, help="the sweep file (YAML; docs/tuning.md)")
    p.add_argument("--out", type=Path, default=None, help="output folder (default runs/sweep-<name>)")
    p.add_argument("--workers", type=int, default=2,
                   help="trials at once (local Ray: also the CPUs it starts with; default 2)")
    p.add_argument("--address", default=None, help="an existing Ray cluster (default: RAY_ADDRESS, else a local one)")
    p.add_argument("--cache", type=Path, default=None,
                   help="recordings and traces, reused across sweeps (default: runs/sweep-cache)")
    p.add_argument("--resume", action="store_true", help="continue the sweep in --out from its saved state")
    p.add_argument("--stop-after", type=int, default=None, metavar="N",
                   help="end after N trials have finished in this session (resume later with --resume)")
    p.add_argument("--trials", type=int, default=None, help="override the spec's number of trials")
    p.add_argument("--check", action="store_true", help="validate the spec and print the plan; run nothing")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help="print sweep.json's content at the end")


def run(args: argparse.Namespace) -> int:
    from app.sweep.spec import SpecError, load_spec

    try:
        spec = load_spec(args.spec)
        if args.trials is not None:
            if args.trials < 1:
                raise SpecError(f"--trials: expected a positive integer, got {args.trials}")
            spec.trials = args.trials
        if args.workers < 1:
            raise SpecError(f"--workers: expected a positive integer, got {args.workers}")
    except SpecError as e:
        print(f"ocslam sweep: error: {e}", file=sys.stderr)
        return 2
    from app.sweep.suite import suite_worlds
    from app.sweep.tune import read_results, total_trials

    worlds = suite_worlds(spec.suite, spec.only)
    out = args.out or Path("runs") / f"sweep-{spec.name}"
    kind = "replay (recorded boxes, SLAM trace)" if spec.replayable else "headless re-run per world"
    print(f"sweep {spec.name}: {total_trials(spec)} trials ({spec.sampler}) of {len(spec.params)} parameters over "
          f"{len(worlds)} worlds, {kind}; objective {spec.objective.describe()}; {spec.scheduler.describe()}; out {out}",
          file=sys.stderr)
    if args.check:
        for p in spec.params:
            rng = p.values if p.values is not None else f"[{p.low:g}, {p.high:g}]" + (f" step {p.step:g}" if p.step else "")
            print(f"  {p.path}: {rng}", file=sys.stderr)
        return 0
    from app.sweep.results import best_row, write_best, write_plots, write_table
    from app.sweep.tune import RESULTS, run_sweep

    info = run_sweep(spec, out, workers=args.workers, address=args.address, cache=args.cache, resume=args.resume,
                     stop_after=args.stop_after, quiet=args.quiet)
    rows = read_results(Path(out) / RESULTS)
    csv_path, md_path = write_table(spec, rows, Path(out))
    best = write_best(spec, rows, Path(out))
    plots = write_plots(spec, rows, Path(out))
    b = best_row(rows)
    info.update(spec=str(args.spec), out=str(out), best=b, best_yaml=str(best) if best else None,
                plots=[str(p) for p in plots])
    (Path(out) / "sweep.json").write_text(json.dumps(info, indent=1, default=float), encoding="utf-8")
    if args.json:
        print(json.dumps(info, indent=1, default=float))
    else:
        n_stopped = sum(not r.get("complete", True) for r in rows)
        stopped = f", {n_stopped} stopped early" if n_stopped else ""
        print(f"{len(rows)}/{info['trials_total']} trials{stopped} ({info['trials_wall_s']} s of trials, "
              f"{info['prepare_s']} s preparing; Ray {info['cluster']['address']}, {info['cluster']['cpus']:g} CPUs)")
        if b is not None:
            print(f"best: objective {b['objective']:.4f} (P {b['mean_precision_strict']:.3f}, R {b['mean_recall']:.3f}, "
                  f"F1 {b['mean_f1']:.3f}) with " + ", ".join(f"{k}={v}" for k, v in b["params"].items()))
        print(f"table: {csv_path}, {md_path}; best config: {best}; plots: {Path(out) / 'plots'}")
    done = len(rows) >= info["trials_total"]
    return 0 if done else 130
