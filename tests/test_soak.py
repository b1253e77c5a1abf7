"""``ocslam bench soak``: its RSS figures (warm start, raw first sample, the floor a world leaves behind),
the heap trim it measures that floor with, its incremental output and its argument checks."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest

from app.bench import soak
from app.cli import main as cli_main


def _world(seed: int, warm_main: float, end_main: float, floor: float | None, *, partial: bool = False) -> dict:
    return {
        "seed": seed, "world_objects": 10, "exceptions": 0, "partial": partial,
        "rss_warm_mib": warm_main + 500.0, "rss_end_mib": end_main + 500.0,
        "rss_warm_main_mib": warm_main, "rss_end_main_mib": end_main,
        "rss_samples": [[0.0, warm_main - 20.0, warm_main + 480.0], [60.0, warm_main, warm_main + 500.0],
                        [90.0, end_main, end_main + 500.0]],
        "rss_trimmed_main_mib": floor, "loop_errors": {"detector": 1}, "skipped_frames": {"no_synced_scan": 3},
        "slam_skipped": {},
    }


def test_summary_starts_at_the_warm_world_and_reports_the_raw_first_sample() -> None:
    res = {"warm_worlds": 1, "worlds": [_world(1, 200.0, 210.0, 150.0), _world(2, 250.0, 260.0, 160.0),
                                        _world(3, 260.0, 275.0, 161.0), _world(4, 255.0, 256.0, 162.0)]}
    soak._summarise(res, 400.0, 800.0, 7200.0)
    assert res["rss_main_start_mib"] == 250.0 and res["rss_main_last_warm_mib"] == 255.0
    assert res["rss_main_growth_pct"] == 2.0  # 255 / 250 - 1
    assert res["rss_main_first_sample_mib"] == 200.0 and res["rss_main_growth_raw_pct"] == 27.5
    assert res["rss_start_mib"] == 750.0 and res["rss_growth_pct"] == pytest.approx(100 * (755 / 750 - 1), abs=0.01)
    assert res["rss_main_floor_mib"] == [150.0, 160.0, 161.0, 162.0]
    assert res["rss_main_floor_growth_pct"] == 1.25  # 162 / 160 - 1
    assert res["rss_main_max_mib"] == 275.0 and res["rss_max_mib"] == 775.0 and res["rss_main_end_mib"] == 256.0
    assert res["loop_errors"] == 4 and res["skipped_frames"] == {"no_synced_scan": 12}
    assert res["worlds_done"] == 4 and res["real_time_factor"] == 0.5 and res["complete"] is False


def test_summary_has_no_growth_before_a_world_after_the_warm_one() -> None:
    """With ``warm_worlds = 1``, two worlds give a start but no growth yet (the second is both ends); a
    partial world counts for the samples but not as done."""
    res = {"warm_worlds": 1, "worlds": [_world(1, 200.0, 210.0, 150.0), _world(2, 250.0, 260.0, None, partial=True)]}
    soak._summarise(res, 100.0, 100.0, 100.0)
    assert res["rss_main_start_mib"] == 250.0 and res["rss_main_growth_pct"] is None
    assert res["rss_main_growth_raw_pct"] == 25.0 and res["rss_main_floor_growth_pct"] is None
    assert res["worlds_done"] == 1 and res["complete"] is True
    res0 = {"warm_worlds": 0, "worlds": res["worlds"]}
    soak._summarise(res0, 100.0, 100.0, 100.0)
    assert res0["rss_main_start_mib"] == 200.0 and res0["rss_main_growth_pct"] == 25.0


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc malloc_trim and /proc RSS")
def test_malloc_trim_hands_freed_heap_pages_back() -> None:
    """Blocks freed below a live one stay resident (glibc cannot shrink the heap past it) until
    ``malloc_trim``: the mechanism behind the RSS step at a world change."""
    code = textwrap.dedent("""
        import json
        from app.bench.soak import rss_mib
        from app.memory import malloc_trim
        blocks = [b"\\x01" * 65536 for _ in range(1600)]   # 100 MiB in heap-sized blocks, pages touched
        keep = blocks[::16]                                # a live block every 1 MiB pins the heap
        del blocks
        before = rss_mib(children=False)
        ok = malloc_trim()
        print(json.dumps({"ok": ok, "before": before, "after": rss_mib(children=False), "kept": len(keep)}))
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    r = json.loads(out.stdout.strip().splitlines()[-1])
    if not r["ok"]:
        pytest.skip("no glibc malloc_trim here")
    assert r["before"] - r["after"] > 50.0, r


@pytest.mark.parametrize("argv, message", [
    (["bench", "soak", "--warm-worlds", "-1"], "--warm-worlds must be 0 or more"),
    (["bench", "soak", "--sample-every", "0"], "--sample-every must be a positive number"),
    (["bench", "soak", "--sample-every", "nan"], "--sample-every must be a positive number"),
])
def test_soak_arguments(argv, message, capsys) -> None:
    rc = cli_main(argv)
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith("pybullet build time")]
    assert rc == 2 and len(lines) == 1 and lines[0].startswith("ocslam: error: ") and message in lines[0], err


@pytest.mark.slow
def test_a_short_soak_writes_its_worlds_as_it_goes(tmp_path) -> None:
    """A real (short) soak without a detector: the output file holds the world's samples, the floor it
    left behind, and the summary; a progress callback sees the world while it runs (marked partial)."""
    from app.config import Config

    cfg = Config.load(None, ["detector.kind=none"])
    seen: list[dict] = []
    w = soak.soak_world(cfg, 99100, sim_budget_s=4.0, warmup_s=2.0, deadline=None, sample_every_s=1.0,
                        progress=lambda r: seen.append(json.loads(json.dumps(r))), progress_every_wall_s=0.0)
    assert seen and all(s["partial"] for s in seen) and w["partial"] is False
    assert seen[-1]["sim_s"] <= w["sim_s"] and len(w["rss_samples"]) >= 3
    assert w["rss_closed_main_mib"] > 0 and w["exceptions"] == 0
    out = tmp_path / "soak.json"
    res = soak.soak(cfg, sim_hours=3.0 / 3600, world_minutes=1.0, warmup_s=1.0, seed0=99100, out=out)
    on_disk = json.loads(out.read_text())
    assert on_disk["sim_s"] == res["sim_s"] >= 3.0 and on_disk["worlds"][0]["rss_samples"]
    assert on_disk["rss_main_first_sample_mib"] is not None and on_disk["exceptions"] == 0
