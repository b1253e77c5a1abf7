"""The replay timeline (app.ui.replay): play, pause, rate, step, seek from the nearest snapshot, loop; and
the web app serving it (viser, no browser)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from test_ros2_bags import write_bag

from app.config import Config
from app.ros2.reader import read_bag
from app.ros2.replay import ReplayCore
from app.ui.replay import ReplayApp, ReplayPlayer


@pytest.fixture(scope="module")
def bag_path(tmp_path_factory) -> Path:
    return write_bag(tmp_path_factory.mktemp("tl") / "room", "mcap")


def make_core(bag_path, snapshot_s=2.0) -> ReplayCore:
    cfg = Config()
    cfg.set("replay.snapshot_period_s", snapshot_s)
    return ReplayCore(cfg, read_bag(bag_path))


def test_play_pause_rate(bag_path):
    p = ReplayPlayer(make_core(bag_path), rate=2.0)
    assert p.duration == pytest.approx(12.01, abs=0.02) and p.position == 0.0
    assert p.tick(now=0.0) == 0  # paused: nothing happens
    p.play()
    p.tick(now=100.0)  # anchors the clock
    p.tick(now=101.0)  # one wall second at 2×: two bag seconds
    assert p.position == pytest.approx(2.0, abs=0.06)
    p.set_rate(8.0)
    p.tick(now=102.0)  # re-anchored at the rate change
    p.tick(now=102.5)
    assert p.position == pytest.approx(6.0, abs=0.06)
    p.pause()
    before = p.position
    p.tick(now=110.0)
    assert p.position == before
    with pytest.raises(ValueError):
        p.set_rate(16.0)


def test_step_goes_to_the_next_scan(bag_path):
    p = ReplayPlayer(make_core(bag_path))
    for k in range(3):
        assert p.step()
        assert p.core.state.counters.scans == k + 1 and not p.playing
        assert p.core.bag.events[p.core.state.index - 1].kind == "scan"


def test_seek_restarts_from_the_nearest_snapshot_and_matches_a_straight_run(bag_path):
    straight = make_core(bag_path)
    straight.run_until(straight.t_start + 9.0)
    p = ReplayPlayer(make_core(bag_path, snapshot_s=2.0))
    p.seek(11.0)  # forward: snapshots taken on the way
    assert len(p.core.snapshots) >= 5
    calls = []
    real = p.core._fresh_state
    p.core._fresh_state = lambda: calls.append(1) or real()
    p.seek(9.0)  # backward: from the snapshot at ≤ 9 s, not from the start
    assert not calls
    assert p.position == pytest.approx(9.0, abs=0.06)
    restored = [s.t - p.t0 for s in p.core.snapshots if s.t <= p.core.t_start + 9.0][-1]
    assert 7.0 - 0.1 <= restored <= 9.0
    a, b = straight.slam.trajectory(), p.core.slam.trajectory()
    assert (a[0] == b[0]).all() and abs(a[1] - b[1]).max() < 1e-9  # the same state as a straight run
    p.seek(0.5)  # before the first snapshot after 0: from the snapshot at 0
    assert p.position <= 0.5 + 1e-9


def test_loop_restarts_at_the_end(bag_path):
    p = ReplayPlayer(make_core(bag_path), rate=8.0, loop=True)
    p.play()
    p.tick(now=0.0)
    p.tick(now=2.0)  # 16 bag seconds: past the end
    assert p.playing and p.position < 1.0 and p.seeks == 1
    q = ReplayPlayer(make_core(bag_path), rate=8.0, loop=False)
    q.play()
    q.tick(now=0.0)
    q.tick(now=2.0)
    assert not q.playing and q.core.done


def test_web_app_serves_the_timeline(bag_path):
    app = ReplayApp(make_core(bag_path), port=0).start()
    try:
        assert app.url.startswith("http://127.0.0.1:")
        app.player.step()
        app._refresh(with_map=True)
        assert app.seek_slider.max == pytest.approx(12.0, abs=0.1)
        assert "paused" in app.status.content and "scans 1" in app.status.content
        app.player.seek(6.0)
        app._refresh(with_map=True)
        assert app.seek_slider.value == pytest.approx(6.0, abs=0.1)
        assert app.grid_image.render_width > 5.0  # the room's map is shown
    finally:
        app.stop()
