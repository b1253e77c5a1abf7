"""Where the soak's RSS goes at a world change: one pipeline per world (YOLO on, frontier exploration for
``--sim`` sim seconds), then after each world's close: this process's RSS, the same after ``malloc_trim(0)``
(``--trim``) and by kind of mapping, Python's allocator arenas in use, the Python objects by type that grew (``gc.get_objects()``), threads, open files and memory
mappings, and with ``--trace`` the memory tracemalloc sees and its top growth (slow: several times the run).
One JSON line per world (docs/benchmarks.md, "Why the RSS steps up at a world change").

    python scripts/soak_memory.py [--worlds 8] [--sim 20] [--same] [--trim] [--trace]
    MALLOC_ARENA_MAX=2 python scripts/soak_memory.py ...           # fewer glibc arenas
    MALLOC_MMAP_THRESHOLD_=131072 python scripts/soak_memory.py ... # glibc's mmap threshold fixed (not dynamic)
"""
import argparse
import collections
import gc
import json
import os
import sys
import threading
import time
import tracemalloc

from app.bench.soak import rss_mib
from app.config import Config
from app.memory import malloc_trim
from app.pipeline import Pipeline
from app.world.generator import random_world


def rss_by_mapping() -> dict[str, float]:
    """Resident MiB of this process by kind of mapping (/proc/self/smaps): glibc's main ``[heap]``,
    anonymous mappings (Python's allocator arenas, glibc's other arenas, large blocks), files, others."""
    out: dict[str, float] = collections.defaultdict(float)
    kind = "other"
    with open("/proc/self/smaps") as f:
        for line in f:
            head = line.split()
            if head and "-" in head[0] and len(head) >= 5 and not head[0].endswith(":"):
                name = head[5] if len(head) > 5 else ""
                kind = "heap" if name == "[heap]" else "anon" if not name else "file" if name.startswith("/") else "other"
            elif head and head[0] == "Rss:":
                out[kind] += int(head[1]) / 1024
    return {k: round(v, 1) for k, v in sorted(out.items())}


def largest_anonymous(n: int = 8) -> list[tuple[int, float]]:
    """The ``n`` anonymous mappings with the most resident memory: ``(size KiB, resident MiB)``
    (8 MiB + 4 KiB: a thread stack, kept in glibc's stack cache after its thread ended; 64 MiB: a glibc
    malloc arena of another thread; 1 MiB: Python's allocator arenas)."""
    maps: list[tuple[int, float]] = []
    size, anon = 0, False
    with open("/proc/self/smaps") as f:
        for line in f:
            head = line.split()
            if head and "-" in head[0] and len(head) >= 5 and not head[0].endswith(":"):
                lo, hi = (int(x, 16) for x in head[0].split("-"))
                size, anon = (hi - lo) // 1024, len(head) <= 5
            elif head and head[0] == "Rss:" and anon:
                maps.append((size, round(int(head[1]) / 1024, 1)))
    return sorted(maps, key=lambda m: -m[1])[:n]


def large_arrays(min_mib: float = 1.0) -> list[str]:
    """numpy arrays of at least ``min_mib`` still reachable from the loaded modules after a world closed,
    each with the path that reaches it. A crawl from ``sys.modules`` through every referent, because a dict
    that holds only arrays is not tracked by the garbage collector (``gc.get_objects`` misses it)."""
    import numpy as np

    found: list[tuple[int, str]] = []
    seen: set[int] = set()
    queue = collections.deque((m, f"sys.modules[{n!r}]") for n, m in list(sys.modules.items()) if m is not None)
    while queue:
        o, path = queue.popleft()
        if id(o) in seen:
            continue
        seen.add(id(o))
        if isinstance(o, np.ndarray):
            if o.base is None and o.nbytes >= min_mib * 2**20:
                found.append((o.nbytes, f"{o.nbytes / 2**20:.1f} MiB {o.dtype}{list(o.shape)} at {path}"))
            continue
        if isinstance(o, (str, bytes, int, float, type(None))):
            continue
        if isinstance(o, dict):
            items = [(v, f"{path}[{k!r}]" if isinstance(k, (str, int)) else f"{path}[…]") for k, v in o.items()]
        else:
            items = [(r, f"{path}.{type(r).__name__}") for r in gc.get_referents(o)]
        if len(path) < 400:
            queue.extend(items)
    return [t for _n, t in sorted(found, reverse=True)[:12]]


def peek_anonymous(min_kib: int = 4000, n: int = 6) -> list[str]:
    """What the largest resident anonymous mappings hold: size, and their bytes read as float64/uint8
    statistics (a grid, an image, …), to tell whose memory they are."""
    import numpy as np

    out = []
    regions = []
    with open("/proc/self/smaps") as f:
        cur = None
        for line in f:
            head = line.split()
            if head and "-" in head[0] and len(head) >= 5 and not head[0].endswith(":"):
                lo, hi = (int(x, 16) for x in head[0].split("-"))
                cur = (lo, hi) if len(head) <= 5 and (hi - lo) // 1024 >= min_kib else None
            elif head and head[0] == "Rss:" and cur is not None:
                regions.append((int(head[1]), cur))
    with open("/proc/self/mem", "rb") as mem:
        for rss, (lo, hi) in sorted(regions, reverse=True)[:n]:
            mem.seek(lo)
            raw = mem.read(min(hi - lo, 1 << 22))
            b = np.frombuffer(raw, np.uint8)
            f64 = np.frombuffer(raw[: len(raw) // 8 * 8], np.float64)
            fin = f64[np.isfinite(f64) & (np.abs(f64) < 1e6)]
            out.append(f"{(hi - lo) // 1024} KiB ({rss / 1024:.1f} resident): zeros {np.mean(b == 0):.2f}, "
                       f"uint8 mean {b.mean():.0f}, float64 plausible {len(fin) / max(len(f64), 1):.2f} "
                       f"(median {np.median(fin) if len(fin) else float('nan'):.3g}), head {raw[16:48].hex()}")
    return out


def pymalloc_arenas() -> int:
    """Python's allocator arenas in use now (``sys._debugmallocstats``'s "arenas allocated current")."""
    import tempfile

    with tempfile.TemporaryFile(mode="w+") as tmp:
        sys.stderr.flush()
        saved = os.dup(2)
        os.dup2(tmp.fileno(), 2)
        try:
            sys._debugmallocstats()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        tmp.seek(0)
        for line in tmp:
            if line.startswith("# arenas allocated current"):
                return int(line.split("=")[1].replace(",", ""))
    return -1


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--worlds", type=int, default=8)
    ap.add_argument("--sim", type=float, default=20.0, help="sim seconds per world")
    ap.add_argument("--seed0", type=int, default=99100)
    ap.add_argument("--same", action="store_true", help="the same world every time")
    ap.add_argument("--trim", action="store_true", help="malloc_trim(0) after every world, and its RSS")
    ap.add_argument("--trace", action="store_true", help="tracemalloc (slow)")
    ap.add_argument("--arrays", action="store_true", help="list the large numpy arrays still held after each world")
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                    help="config override (e.g. detector.kind=none to leave the detector out)")
    a = ap.parse_args()
    cfg = Config.load(None, ["detector.kind=yolo", *a.overrides])

    def types() -> collections.Counter:
        return collections.Counter(type(o).__name__ for o in gc.get_objects())

    if a.trace:
        tracemalloc.start(3)
    prev_snap, prev_types = None, types()
    print(json.dumps({"start_rss_mib": round(rss_mib(children=False), 1)}), flush=True)
    for i in range(a.worlds):
        seed = a.seed0 + (0 if a.same else i)
        t0 = time.perf_counter()
        pipe = Pipeline(cfg, world=random_world(seed))
        pipe.explore()
        while pipe.time < a.sim and not (pipe.drive_mode == "idle" and pipe.nav_status):
            pipe.step()
        live = rss_mib(children=False)
        pipe.close()
        del pipe
        gc.collect()
        rec = {"world": i, "seed": seed, "wall_s": round(time.perf_counter() - t0, 1), "rss_live_mib": round(live, 1),
               "rss_closed_mib": round(rss_mib(children=False), 1), "threads": threading.active_count(),
               "fds": len(os.listdir("/proc/self/fd")), "maps": sum(1 for _ in open("/proc/self/maps")),
               "py_blocks": sys.getallocatedblocks()}
        if a.trim and malloc_trim():
            rec["rss_trimmed_mib"] = round(rss_mib(children=False), 1)
        rec["rss_by_mapping_mib"] = rss_by_mapping()
        rec["pymalloc_arenas"] = pymalloc_arenas()
        rec["largest_anonymous"] = largest_anonymous()
        if a.arrays:
            rec["large_arrays"] = large_arrays()
            rec["anonymous_contents"] = peek_anonymous()
        if a.trace:
            rec["traced_mib"] = round(tracemalloc.get_traced_memory()[0] / 2**20, 1)
            snap = tracemalloc.take_snapshot().filter_traces([tracemalloc.Filter(False, tracemalloc.__file__)])
            if prev_snap is not None:
                rec["traced_growth"] = [f"{st.size_diff / 1024:+.0f} KiB {st.traceback[0].filename}:{st.traceback[0].lineno}"
                                        for st in snap.compare_to(prev_snap, "lineno")[:6]]
            prev_snap = snap
            large = sorted((t for t in snap.traces if t.size >= 512 * 1024), key=lambda t: -t.size)
            rec["traced_large"] = [f"{t.size / 2**20:.1f} MiB {t.traceback[-1].filename}:{t.traceback[-1].lineno}"
                                   for t in large[:8]]  # blocks Python or numpy allocated and still hold
        t = types()
        rec["objects_grown"] = (t - prev_types).most_common(6)
        prev_types = t
        print(json.dumps(rec), flush=True)


if __name__ == "__main__":  # the render worker is a spawned process: it imports this module
    main()
