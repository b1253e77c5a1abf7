"""``ocslam bench ui``: server CPU per UI tick and bytes per tick per client at 10 Hz, with 1 and 5 clients.

Clients are protocol-level viser clients (``app.bench.wsclient``): they receive and decode exactly what
a browser would. Target: ≤ 150 kB/s per client at 10 Hz.

``--churn SECONDS``: clients that disconnect mid-stream. For each client count, three equal windows:
steady, churn (every SECONDS a third of the clients vanish, alternately dropping the TCP connection
without a close handshake and closing cleanly, and as many new ones connect), steady again. Reported:
the loop's real-time factor in each window, this process's RSS after each window, the server's client
count at the end (goal: the loop's real-time factor and memory unchanged, no client left behind).

    ocslam bench ui --clients 10 --churn 2 --seconds 30
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import time

from app.bench.common import print_json, table
from app.commands.run import add_config_arguments, config_from_args


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_config_arguments(p)
    p.add_argument("--clients", type=int, nargs="+", default=[1, 5], help="client counts to measure")
    p.add_argument("--seconds", type=float, default=15.0, help="measurement window per client count")
    p.add_argument("--hz", type=float, default=10.0, help="UI update rate")
    p.add_argument("--churn", type=float, default=0.0, metavar="SECONDS",
                   help="clients disconnect mid-stream every SECONDS (0: off); see the module docstring")
    p.add_argument("--json", action="store_true")


def measure(cfg, n_clients: int, seconds: float) -> dict:
    from app.bench.wsclient import FakeViserClient
    from app.server import OcslamApp

    cfg = cfg.copy()
    cfg.set("server.port", 0)
    with contextlib.redirect_stdout(io.StringIO()):  # viser's banner would break --json
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
        with contextlib.redirect_stdout(io.StringIO()):
            app.stop()


def _rss_mib() -> float:
    from app.bench.soak import rss_mib

    return round(rss_mib(), 1)


def measure_churn(cfg, n_clients: int, seconds: float, every: float) -> dict:
    """Steady / churn / steady windows of ``seconds / 3`` each (see the module docstring)."""
    import random

    from app.bench.wsclient import FakeViserClient
    from app.server import OcslamApp

    cfg = cfg.copy()
    cfg.set("server.port", 0)
    with contextlib.redirect_stdout(io.StringIO()):  # viser's banner would break --json
        app = OcslamApp(cfg).start()
    rng = random.Random(0)
    window = seconds / 3.0
    clients: list = []
    dropped = aborted = 0
    try:
        app.submit(lambda p: p.follow_route(cfg.sim.route))
        clients = [FakeViserClient(app.port).connect() for _ in range(n_clients)]
        time.sleep(3.0)  # initial scene transfer, warm-up

        def sample(duration: float, churn: bool) -> tuple[float, float]:
            nonlocal dropped, aborted
            sim0, w0 = app.pipeline.time, time.perf_counter()
            next_churn = w0 + every if churn else float("inf")
            while time.perf_counter() - w0 < duration:
                time.sleep(0.05)
                if time.perf_counter() >= next_churn:
                    for i in rng.sample(range(len(clients)), max(1, len(clients) // 3)):
                        if (dropped + aborted) % 2 == 0:
                            clients[i].abort()  # vanishes mid-stream: no close handshake
                            aborted += 1
                        else:
                            clients[i].close()
                            dropped += 1
                        clients[i] = FakeViserClient(app.port).connect()
                    next_churn += every
            wall = time.perf_counter() - w0
            return round((app.pipeline.time - sim0) / wall, 3), _rss_mib()

        rss_start = _rss_mib()
        rtf_a, rss_a = sample(window, churn=False)
        rtf_b, rss_b = sample(window, churn=True)
        rtf_c, rss_c = sample(window, churn=False)
        time.sleep(1.0)
        server_clients = len(app.server.get_clients())
        return {
            "clients": n_clients,
            "churn_every_s": every,
            "disconnects": dropped + aborted,
            "aborted_mid_stream": aborted,
            "closed": dropped,
            "rtf_steady_before": rtf_a,
            "rtf_churn": rtf_b,
            "rtf_steady_after": rtf_c,
            "rss_start_mib": rss_start,
            "rss_after_steady_mib": rss_a,
            "rss_after_churn_mib": rss_b,
            "rss_end_mib": rss_c,
            "rss_growth_pct": round(100.0 * (rss_c / rss_a - 1.0), 2) if rss_a else None,
            "server_clients_end": server_clients,
            "loop_errors": dict(app.pipeline.counters.errors),
            "cores": os.cpu_count(),
        }
    finally:
        for c in clients:
            c.close()
        with contextlib.redirect_stdout(io.StringIO()):
            app.stop()


def run(args: argparse.Namespace) -> int:
    cfg = config_from_args(args)
    cfg.set("ui.update_hz", args.hz)
    if args.churn and args.churn > 0:
        rows = [measure_churn(cfg, n, args.seconds, args.churn) for n in args.clients]
        if args.json:
            print_json({"hz": args.hz, "churn": rows})
            return 0
        keys = ["clients", "disconnects", "rtf_steady_before", "rtf_churn", "rtf_steady_after", "rss_after_steady_mib",
                "rss_after_churn_mib", "rss_end_mib", "rss_growth_pct", "server_clients_end"]
        table(keys, [[r[k] for k in keys] for r in rows],
              title=f"UI at {args.hz:g} Hz with clients vanishing every {args.churn:g} s (goal: RTF and RSS unchanged)")
        return 0
    rows = [measure(cfg, n, args.seconds) for n in args.clients]
    if args.json:
        print_json({"hz": args.hz, "results": rows})
        return 0
    keys = ["clients", "tick_hz", "ui_ms_per_tick", "process_cpu_pct", "bytes_per_tick_per_client",
            "kB_per_s_per_client", "max_kB_per_s_per_client", "real_time_factor"]
    table(keys, [[r[k] for k in keys] for r in rows], title=f"UI at {args.hz:g} Hz (target ≤ 150 kB/s per client)")
    print("process_cpu_pct includes the simulation loop running in real time; ui_ms_per_tick is the scene+panel update.")
    return 0
