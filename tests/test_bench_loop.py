"""``ocslam bench loop``: the JSON keys other tools read, and ``--record``'s with/without pair."""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest


def test_bench_loop_record_reports_the_recording_cost_and_leaves_no_bag() -> None:
    before = set(Path(tempfile.gettempdir()).glob("ocslam-bench-loop-*"))
    r = subprocess.run(
        [sys.executable, "-m", "app", "bench", "loop", "--duration", "3", "--record", "--json",
         "--set", "detector.kind=none", "--set", "sim.renderer=tiny"],
        capture_output=True, text=True, timeout=400,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    res = json.loads(r.stdout[r.stdout.index("{"):])
    assert res["recording"] is True and res["sim_time_s"] >= 3.0
    assert res["real_time_factor"] > 0 and res["real_time_factor_without_recording"] > 0
    expected = 100.0 * (1.0 - res["real_time_factor"] / res["real_time_factor_without_recording"])
    assert res["recording_cost_pct"] == pytest.approx(expected, abs=0.06)
    assert res["bag_mb"] > 0 and {"renderer", "camera_size", "stages_ms", "real_time_factor"} <= set(res)
    assert set(Path(tempfile.gettempdir()).glob("ocslam-bench-loop-*")) == before


def test_charged_time_counts_in_the_stage_total_without_a_call() -> None:
    """The SLAM's map update inside the fusion's call is the SLAM's time: it adds to the SLAM's total (and
    its per-scan figure) without counting as a scan."""
    from app.loop.stages import StageTimer

    t = StageTimer()
    t.add("slam", 0.004)
    t.add("slam", 0.002)
    t.charge("slam", 0.003)
    t.add("consciousness", 0.005)
    assert t.calls["slam"] == 2 and t.total_s["slam"] == pytest.approx(0.009)
    assert t.per_call_ms()["slam"] == pytest.approx(4.5) and t.per_call_ms()["consciousness"] == pytest.approx(5.0)
