"""``ocslam bench ui``: server CPU per UI tick and bytes per tick per client at 10 Hz, with 1 and 5 clients.

Clients are protocol-level viser clients (``app.bench.wsclient``): they receive and decode exactly what
a browser would. Target: ≤ 150 kB/s per client at 10 Hz.
"""

from __future__ import annotations

import argparse
import os
import time

from app.bench.common import print_json, table
from app.commands.run import add_config_arguments, config_from_args


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_config_arguments(p)
    p.add_argument("--clients", type=int, nargs="+", default=[1, 5], help="client counts to measure")
    p.add_argument("--seconds", type=float, default=15.0, help="measurement window per client count")
    p.add_argument("--hz", type=float, default=10.0, help="UI update rate")
    p.add_argument("--json", action="store_true")


def measure(cfg, n_clients: int, seconds: float) -> dict:
    from app.bench.wsclient import FakeViserClient
    from app.server import OcslamApp

    cfg = cfg.copy()
    cfg.set("server.port", 0)
    app = OcslamApp(cfg).start()
    try:
        app.submit(lambda p: p.follow_route(cfg.sim.route))
        clients = [FakeViserClient(app.port).connect() for _ in range(n_clients)]
        time.sleep(3.0)  # initial scene transfer, warm-up
        b0 = [c.stats.bytes for c in clients]
        f0 = [c.stats.frames for c in clients]
        ticks0, ui0 = app.ticks, app.pipeline.timer.total_s.get("ui", 0.0)
        cpu0, w0 = time.process_time(), time.perf_counter()
        time.sleep(seconds)
        cpu1, w1 = time.process_time(), time.perf_counter()
        ticks = app.ticks - ticks0
        ui = app.pipeline.timer.total_s.get("ui", 0.0) - ui0
        per_client_bytes = [c.stats.bytes - b for c, b in zip(clients, b0)]
        per_client_frames = [c.stats.frames - f for c, f in zip(clients, f0)]
        for c in clients:
            c.close()
        wall = w1 - w0
        kbps = [b / wall / 1e3 for b in per_client_bytes]
        return {
            "clients": n_clients,
            "ticks": ticks,
            "tick_hz": round(ticks / wall, 2),
            "ui_ms_per_tick": round(1e3 * ui / max(ticks, 1), 3),
            "process_cpu_pct": round(100 * (cpu1 - cpu0) / wall, 1),
            "bytes_per_tick_per_client": round(sum(per_client_bytes) / n_clients / max(ticks, 1), 1),
            "kB_per_s_per_client": round(sum(kbps) / n_clients, 2),
            "max_kB_per_s_per_client": round(max(kbps), 2),
            "frames_per_s_per_client": round(sum(per_client_frames) / n_clients / wall, 2),
            "real_time_factor": round(app.real_time_factor, 2),
            "cores": os.cpu_count(),
        }
    finally:
        app.stop()


def run(args: argparse.Namespace) -> int:
    cfg = config_from_args(args)
    cfg.set("ui.update_hz", args.hz)
    rows = [measure(cfg, n, args.seconds) for n in args.clients]
    if args.json:
        print_json({"hz": args.hz, "results": rows})
        return 0
    keys = ["clients", "tick_hz", "ui_ms_per_tick", "process_cpu_pct", "bytes_per_tick_per_client",
            "kB_per_s_per_client", "max_kB_per_s_per_client", "real_time_factor"]
    table(keys, [[r[k] for k in keys] for r in rows], title=f"UI at {args.hz:g} Hz (target ≤ 150 kB/s per client)")
    print("process_cpu_pct includes the simulation loop running in real time; ui_ms_per_tick is the scene+panel update.")
    return 0
