"""Real browser: the replay timeline (play, pause, step, seek) in headless chromium through Playwright."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from browser import browser_page, screenshot, wait_for
from test_ros2_bags import write_bag

from app.config import Config
from app.ros2.reader import read_bag
from app.ros2.replay import ReplayCore
from app.ui.replay import ReplayApp

pytestmark = [pytest.mark.browser, pytest.mark.slow]


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    bag = write_bag(tmp_path_factory.mktemp("br") / "room", "mcap")
    a = ReplayApp(ReplayCore(Config(), read_bag(bag)), port=0, rate=1.0).start()
    try:
        yield a
    finally:
        a.stop()


def test_timeline_play_pause_step_seek(app):
    p = app.player
    with browser_page(app.url) as (page,):
        page.get_by_role("button", name="Play").wait_for(timeout=60_000)
        page.get_by_role("button", name="Play").click()
        wait_for(lambda: p.playing and p.position > 1.0, what="playback to advance")
        page.get_by_role("button", name="Pause").click()
        wait_for(lambda: not p.playing, what="pause")
        at = p.position
        page.get_by_role("button", name="Step (next scan)").click()
        wait_for(lambda: p.position > at, what="a step")
        slider = page.get_by_role("slider").first
        slider.focus()
        page.keyboard.press("End")  # the slider to the bag's end: a seek
        wait_for(lambda: p.seeks >= 1 and p.position > 11.0, what="the seek")
        screenshot(page, "ros2-replay-timeline")
        assert p.core.state.counters.scans >= 55
