"""SLAM on a CARMEN log against the Kümmerle et al. (2009) ground-truth relations.

    ocslam bench slam DIR [--json] [--out DIR] [--limit-seconds S]

DIR holds one CARMEN log (``*.clf.bz2``, ``*.clf``, ``*.log``, ``*.gz``) and one ``*.relations`` file
(for example ``../shared/datasets/intel``). The whole log runs through :class:`app.ocslam.slam.Slam` with
the default :class:`~app.ocslam.config.SlamConfig` (one parameter set for every log), then every relation
is scored on the corrected trajectory (poses at the scans' own stamps). The report, the trajectory
(TUM), the map (PNG, and map_server YAML + PGM) go to ``--out`` (default ``runs/bench-slam-<name>/``).

Scans are fed in file order. Some logs (Intel) have ipc timestamps that step backwards by up to 0.6 s
although the file order is the true order; such scans get a stamp just after their predecessor for
the SLAM, and relations are matched to scans by their exact original stamps.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import platform
import resource
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from app.bench.common import fmt, print_json, table
from app.ocslam.config import SlamConfig, coerce_value
from app.ocslam.messages import LaserScan, OccupancyGrid
from app.ocslam.se2 import Pose2, interpolate
from app.ocslam.slam import Slam, read_carmen, read_relations
from app.ocslam.slam.metrics import Relations, relation_errors
from app.ocslam.slam.tum import format_tum

#: Published mean ± std absolute errors (m, °) and wall-clock (s) — Hess et al. 2016, Table II / V;
#: graph mapping as quoted there from Kümmerle et al. 2009.
PUBLISHED: dict[str, list[dict]] = {
    "intel": [
        {"method": "Cartographer (Hess et al. 2016)", "trans": (0.0229, 0.0239), "rot": (0.453, 1.335), "wall_s": 179.0},
        {"method": "Graph mapping (Kümmerle et al. 2009)", "trans": (0.031, 0.026), "rot": (1.3, 4.7), "wall_s": None},
    ],
    "aces": [
        {"method": "Cartographer (Hess et al. 2016)", "trans": (0.0375, 0.0426), "rot": (0.373, 0.469), "wall_s": 41.0},
        {"method": "Graph mapping (Kümmerle et al. 2009)", "trans": (0.044, 0.044), "rot": (0.4, 0.4), "wall_s": None},
    ],
}

_LOG_SUFFIXES = (".clf.bz2", ".clf", ".log", ".log.gz", ".clf.gz", ".log.bz2")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("dir", type=Path, help="directory with one CARMEN log and one .relations file")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    p.add_argument("--out", type=Path, default=None, help="output directory (default runs/bench-slam-<name>/)")
    p.add_argument("--limit-seconds", type=float, default=None, help="only the first S seconds of data")
    p.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", help="override a SlamConfig field (experiments only)"
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def _find(d: Path) -> tuple[Path, Path]:
    if not d.is_dir():
        raise FileNotFoundError(f"{d}: not a directory")
    logs = sorted(f for f in d.iterdir() if f.is_file() and any(f.name.endswith(s) for s in _LOG_SUFFIXES))
    rels = sorted(d.glob("*.relations"))
    if len(logs) != 1:
        raise FileNotFoundError(f"{d}: expected one CARMEN log ({', '.join(_LOG_SUFFIXES)}), found {len(logs)}")
    if len(rels) != 1:
        raise FileNotFoundError(f"{d}: expected one .relations file, found {len(rels)}")
    return logs[0], rels[0]


def _dataset_name(log: Path) -> str:
    name = log.name
    for s in _LOG_SUFFIXES:
        if name.endswith(s):
            return name[: -len(s)]
    return log.stem


def map_image(grid: OccupancyGrid) -> np.ndarray:
    """``(H, W)`` uint8 picture of the grid, north up: black occupied, white free, grey unknown."""
    d = grid.data.astype(np.int16)
    img = np.where(d < 0, 160, 255 - np.clip(d, 0, 100) * 255 // 100).astype(np.uint8)
    return np.flipud(img)


def _cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from app.ocslam.mapio import save_map

    log_path, rel_path = _find(Path(args.dir))
    name = _dataset_name(log_path)
    out = Path(args.out) if args.out else Path("runs") / f"bench-slam-{name}"
    cfg = SlamConfig()
    import dataclasses

    fields = {f.name: f for f in dataclasses.fields(cfg)}
    for kv in args.set:
        key, _, val = kv.partition("=")
        key = key.removeprefix("slam.")
        if key not in fields:
            print(f"ocslam bench slam: unknown SlamConfig field {key!r}", file=sys.stderr)
            return 2
        setattr(cfg, key, coerce_value("slam", fields[key], val))

    load_before = os.getloadavg()
    t_read = time.perf_counter()
    log = read_carmen(log_path)
    rel = read_relations(rel_path)
    read_s = time.perf_counter() - t_read
    n = len(log)
    if args.limit_seconds is not None:
        n = int(np.searchsorted(log.stamps, log.stamps[0] + args.limit_seconds, side="right"))
        n = max(1, n)
    slam = Slam(cfg, log.T_base_scan)
    t0, c0 = time.perf_counter(), _cpu_s()
    last = -np.inf
    bar = tqdm(total=n, desc=f"slam {name}", unit="scan", file=sys.stderr, disable=args.no_progress, mininterval=1.0)
    for i in range(n):
        sc = log.scan(i)
        st = max(sc.stamp, np.nextafter(last, np.inf)) if np.isfinite(last) else sc.stamp
        last = st
        if st != sc.stamp:
            sc = LaserScan(st, sc.angle_min, sc.angle_increment, sc.range_min, sc.range_max, sc.ranges, sc.frame_id)
        slam.process(sc, Pose2.from_array(log.odom[i]))
        if i % 200 == 0:
            bar.set_postfix(kf=len(slam.keyframes), loops=int(slam.pose_graph().is_loop.sum()), refresh=False)
        bar.update(1)
    slam.optimize(iterations=30)
    wall_s = time.perf_counter() - t0
    cpu_s = _cpu_s() - c0
    bar.close()
    grid = slam.occupancy_grid(budget=10**9)
    load_after = os.getloadavg()

    # poses at the scans' own (original) stamps, in file order
    _, est = slam.trajectory()
    if len(est) != n:
        raise RuntimeError(f"trajectory has {len(est)} poses for {n} scans (skipped: {dict(slam.skipped)})")
    stamps = log.stamps[:n]
    index = {float(t): i for i, t in enumerate(stamps)}
    t_end = float(stamps.max())
    keep = np.array([(a in index or a <= t_end) and (b in index or b <= t_end) for a, b in zip(rel.t1, rel.t2)], bool)
    rel = Relations(rel.t1[keep], rel.t2[keep], rel.motion[keep])
    order = np.argsort(stamps, kind="stable")

    def lookup(poses: np.ndarray, t: np.ndarray) -> np.ndarray:
        idx = np.array([index.get(float(v), -1) for v in t])
        out_p = interpolate(t, stamps[order], poses[order])
        out_p[idx >= 0] = poses[idx[idx >= 0]]
        return out_p

    pseudo = np.arange(len(rel) * 2, dtype=np.float64)  # evaluate on looked-up poses directly
    def errors(poses: np.ndarray):
        p = np.empty((2 * len(rel), 3))
        p[0::2] = lookup(poses, rel.t1)
        p[1::2] = lookup(poses, rel.t2)
        r = Relations(pseudo[0::2], pseudo[1::2], rel.motion)
        return relation_errors(pseudo, p, r, max_gap_s=0.25)

    res = errors(est).summary()
    odo = errors(log.odom[:n]).summary()
    duration = float(stamps.max() - stamps.min()) if n > 1 else 0.0
    g = slam.pose_graph()
    report = {
        "dataset": name,
        **res,
        "odom_trans_mean_m": odo["trans_mean_m"],
        "odom_trans_std_m": odo["trans_std_m"],
        "odom_rot_mean_deg": odo["rot_mean_deg"],
        "odom_rot_std_deg": odo["rot_std_deg"],
        "wall_s": wall_s,
        "cpu_s": cpu_s,
        "read_s": read_s,
        "duration_s": duration,
        "scans": n,
        "keyframes": int(len(g.nodes)),
        "edges": int(len(g.edges)),
        "loop_edges": int(g.is_loop.sum()),
        "loop_searches": int(slam.loops.searches),
        "corrections": int(slam.correction_count),
        "skipped": dict(slam.skipped),
        "stats": dict(slam.stats),
        "load_avg_before": list(load_before),
        "load_avg_after": list(load_after),
        "cpus": os.cpu_count(),
        "machine": platform.machine(),
        "python": platform.python_version(),
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "command": "ocslam bench slam " + " ".join(sys.argv[3:] if sys.argv[1:3] == ["bench", "slam"] else sys.argv[1:]),
        "published": PUBLISHED.get(name.lower(), []),
        "out": str(out),
    }
    out.mkdir(parents=True, exist_ok=True)
    (out / "trajectory.tum").write_text(format_tum(stamps, est))
    (out / "odometry.tum").write_text(format_tum(stamps, log.odom[:n]))
    cv2.imwrite(str(out / "map.png"), map_image(grid))
    save_map(grid, out / "map.yaml")
    (out / "report.json").write_text(json.dumps(report, indent=1, default=float) + "\n")

    rows = [
        ["OCSLAM (this run)", f"{fmt(res['trans_mean_m'])} ± {fmt(res['trans_std_m'])}", f"{fmt(res['trans_sq_mean_m2'])} ± {fmt(res['trans_sq_std_m2'])}",
         f"{fmt(res['rot_mean_deg'])} ± {fmt(res['rot_std_deg'])}", f"{fmt(res['rot_sq_mean_deg2'])} ± {fmt(res['rot_sq_std_deg2'])}", f"{wall_s:.1f}"],
        ["raw odometry", f"{fmt(odo['trans_mean_m'])} ± {fmt(odo['trans_std_m'])}", f"{fmt(odo['trans_sq_mean_m2'])} ± {fmt(odo['trans_sq_std_m2'])}",
         f"{fmt(odo['rot_mean_deg'])} ± {fmt(odo['rot_std_deg'])}", f"{fmt(odo['rot_sq_mean_deg2'])} ± {fmt(odo['rot_sq_std_deg2'])}", "–"],
    ]
    for p in PUBLISHED.get(name.lower(), []):
        rows.append([p["method"], f"{p['trans'][0]} ± {p['trans'][1]}", "–", f"{p['rot'][0]} ± {p['rot'][1]}", "–",
                     "–" if p["wall_s"] is None else f"{p['wall_s']:.0f}"])
    title = (
        f"SLAM on {name}: {res['relations']} relations, {n} scans, {duration:.0f} s of data, "
        f"wall {wall_s:.1f} s (CPU {cpu_s:.1f} s, load {load_before[0]:.1f}→{load_after[0]:.1f} on {os.cpu_count()} CPUs)"
    )
    headers = ["method", "trans abs (m)", "trans² (m²)", "rot abs (°)", "rot² (°²)", "wall (s)"]
    if args.json:
        print_json(report)
        import io

        buf = io.StringIO()
        text = table(headers, rows, title=title, file=buf)
    else:
        text = table(headers, rows, title=title)
        print(f"keyframes {len(g.nodes)}, loop edges {int(g.is_loop.sum())}, outputs in {out}/")
    (out / "report.md").write_text(text + "\n")
    return 0
