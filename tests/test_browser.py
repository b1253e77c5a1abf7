"""Real browser: headless Debian chromium through Playwright against the running app (small viewport).

Never asserts frame rates: only outcomes, with generous timeouts. Screenshots go to test-artifacts/.
"""

from __future__ import annotations

import http.server
import threading
import time

import numpy as np
import pytest
from browser import (
    app_state,
    browser_page,
    describe_failures_with,
    focus_canvas,
    hold_key,
    screenshot,
    wait_for,
)

from app.config import Config
from app.server import OcslamApp

pytestmark = [pytest.mark.browser, pytest.mark.slow, pytest.mark.timeout(300)]


@pytest.fixture(scope="module")
def app():
    cfg = Config.load(None, ["detector.kind=none", "server.port=0"])
    a = OcslamApp(cfg).start()
    describe_failures_with(lambda: app_state(a))
    try:
        yield a
    finally:
        describe_failures_with(None)
        a.stop()


@pytest.fixture(scope="module")
def page(app):
    with browser_page(app.url) as (p,):
        p.get_by_role("button", name="Forward").wait_for(timeout=60_000)
        yield p


def _png_variance(path) -> float:
    import cv2

    img = cv2.imread(str(path))
    return float(img.astype(np.float32).std())


def test_page_shows_the_scene(app, page) -> None:
    wait_for(lambda: len(app.server.get_clients()) >= 1, what="the browser to register")
    time.sleep(3.0)
    shot = screenshot(page, "01-app-overview")
    assert _png_variance(shot) > 20  # not a blank page: the apartment, robot and panel are drawn
    assert page.get_by_text("OCSLAM").first.is_visible()
    assert page.get_by_role("tab", name="Drive").is_visible()


def test_key_i_drives_the_robot_forward(app, page) -> None:
    focus_canvas(page)
    start = app.pipeline.sim.true_pose()
    hold_key(page, "i", lambda: app.pipeline.sim.true_pose().distance(start) > 0.15, what="the robot to move")
    d = start.between(app.pipeline.sim.true_pose())
    assert d.x > 0.15 and abs(d.y) < 0.05, d  # forward along base_footprint +x
    page.keyboard.press("k")
    screenshot(page, "02-after-teleop")


def test_a_foreign_origin_is_refused(app, page) -> None:
    """A page served from another origin tries to open the app's WebSocket: the server answers 403."""
    html = f"""<html><body><div id=r>pending</div><script>
    const ws = new WebSocket("ws://127.0.0.1:{app.port}", "viser-v1.1.1");
    ws.onopen = () => document.getElementById("r").textContent = "open";
    ws.onerror = () => document.getElementById("r").textContent = "refused";
    </script></body></html>""".encode()

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self):  # noqa: N802
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.end_headers()
            self.wfile.write(html)

        def log_message(self, *a):
            pass

    evil = http.server.HTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=evil.serve_forever, daemon=True).start()
    refused_before = app.origin_policy.refused
    try:
        other = page.context.new_page()
        other.goto(f"http://127.0.0.1:{evil.server_address[1]}/")
        other.wait_for_function("document.getElementById('r').textContent !== 'pending'", timeout=20_000)
        assert other.inner_text("#r") == "refused"
        assert app.origin_policy.refused > refused_before
        other.close()
    finally:
        evil.shutdown()
