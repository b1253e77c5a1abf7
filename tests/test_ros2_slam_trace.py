"""SLAM traces: a headless ``--reuse-detections`` replay keeps the SLAM's side of the replay, and the next one
with the same bag and SLAM settings runs only the object map, with the same results as the full replay."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from app.commands import replay as replay_cmd
from app.config import Config
from app.ros2.slam_trace import TraceReplay, load_trace, trace_can_run, trace_key

pytestmark = pytest.mark.slow  # one 8 s headless run, replayed five times

DURATION = 8.0


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    from app.commands.run import run_headless

    out = tmp_path_factory.mktemp("rec") / "run"
    cfg = Config()
    cfg.set("camera.async_render", False)
    cfg.set("detector.kind", "oracle")  # boxes from the simulator: no model needed, the same boxes in the bag
    assert run_headless(cfg, duration=DURATION, out=out, quiet=True, record="") == 0
    return out / "bag"


def _replay(bag: Path, out: Path, cache: Path, *extra: str) -> int:
    p = argparse.ArgumentParser()
    replay_cmd.add_arguments(p)
    args = p.parse_args([str(bag), "--headless", "--reuse-detections", "--quiet", "--cache-dir", str(cache),
                         "--out", str(out), *extra])
    return replay_cmd.run(args)


def _results(d: Path) -> dict[str, bytes]:
    return {n: (d / n).read_bytes() for n in ("objects.json", "trajectory_slam.tum", "map.pgm", "trajectory_odom.tum")}


def test_the_second_replay_uses_the_trace_and_gives_the_same_run_directory(bag, tmp_path):
    cache = tmp_path / "cache"
    assert _replay(bag, tmp_path / "full", cache, "--slam-trace", "off") == 0
    assert not cache.exists()  # off: nothing kept
    assert _replay(bag, tmp_path / "first", cache) == 0
    traces = list(cache.glob("*.pkl"))
    assert len(traces) == 1
    assert _replay(bag, tmp_path / "second", cache) == 0
    s1 = json.loads((tmp_path / "first" / "summary.json").read_text())
    s2 = json.loads((tmp_path / "second" / "summary.json").read_text())
    assert "slam_trace" not in s1 and s2["slam_trace"] == traces[0].stem
    assert s2["objects_recall"] == s1["objects_recall"] and s2["slam_ate_rmse_m"] == s1["slam_ate_rmse_m"]
    full = _results(tmp_path / "full")
    assert _results(tmp_path / "first") == full
    assert _results(tmp_path / "second") == full


def test_other_consciousness_constants_replay_from_the_trace_as_in_the_full_replay(bag, tmp_path):
    cache = tmp_path / "cache"
    assert _replay(bag, tmp_path / "build", cache) == 0
    change = ("--set", "consciousness.max_object_range_m=1.2", "--set", "consciousness.frames_for_presence=3")
    assert _replay(bag, tmp_path / "traced", cache, *change) == 0
    assert "slam_trace" in json.loads((tmp_path / "traced" / "summary.json").read_text())
    assert _replay(bag, tmp_path / "full", cache, "--slam-trace", "off", *change) == 0
    a = json.loads((tmp_path / "traced" / "objects.json").read_text())
    b = json.loads((tmp_path / "full" / "objects.json").read_text())
    assert a == b
    # and the change did change the map (the test would not see a trace that ignored the constants)
    c = json.loads((tmp_path / "build" / "objects.json").read_text())
    assert a["detections"] != c["detections"]


def test_the_key_follows_the_slam_and_the_fixed_consciousness_settings(bag):
    cfg = Config()
    k0 = trace_key(bag, cfg)
    assert trace_key(bag, cfg) == k0
    cfg.set("consciousness.island_threshold_m", 0.2)
    assert trace_key(bag, cfg) == k0  # a trial's constant: same trace
    for key, value in (("slam.enabled", False), ("consciousness.corner_check", False),
                       ("consciousness.sync_tolerance_s", 0.05)):
        c = Config()
        c.set(key, value)
        assert trace_key(bag, c) != k0, key
    assert trace_key(bag, Config(), start=2.0) != k0


def test_a_corrupt_trace_is_rebuilt_and_a_mismatched_one_refused(bag, tmp_path):
    cache = tmp_path / "cache"
    key = trace_key(bag, Config())
    cache.mkdir()
    (cache / f"{key}.pkl").write_bytes(b"not a pickle")
    assert load_trace(cache / f"{key}.pkl") is None
    assert _replay(bag, tmp_path / "out", cache) == 0  # falls back to the full replay and rewrites it
    trace = load_trace(cache / f"{key}.pkl")
    assert trace is not None and trace.key == key
    cfg = Config()
    cfg.set("consciousness.mode", "seed")
    assert "mode" in (trace_can_run(trace, cfg) or "")
    with pytest.raises(ValueError):
        TraceReplay(trace, cfg)


def test_no_trace_is_kept_unless_the_user_chose_a_cache(bag, tmp_path, monkeypatch):
    """Without ``--cache-dir`` or ``$OCSLAM_CACHE_DIR`` the replay writes nothing outside its run directory."""
    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.delenv("OCSLAM_CACHE_DIR", raising=False)
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    p = argparse.ArgumentParser()
    replay_cmd.add_arguments(p)
    args = p.parse_args([str(bag), "--headless", "--reuse-detections", "--quiet", "--out", str(tmp_path / "run")])
    assert replay_cmd._trace_path(args) is None
    assert replay_cmd.run(args) == 0
    assert list(home.rglob("*")) == []
    monkeypatch.setenv("OCSLAM_CACHE_DIR", str(tmp_path / "cache"))
    key_path = replay_cmd._trace_path(args)
    assert key_path is not None and key_path[1].parent == tmp_path / "cache" / "replay"
