"""Real-browser helpers: headless Debian chromium driven by Playwright (no `playwright install`)."""

from __future__ import annotations

import os
import shutil
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

ARTIFACTS = Path(__file__).resolve().parents[1] / "test-artifacts"
CHROMIUM_FLAGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-quic",
    "--no-first-run",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--use-gl=angle",
]
VIEWPORT = {"width": 800, "height": 600}


def chromium_path() -> str | None:
    for cand in (os.environ.get("OCSLAM_CHROMIUM"), shutil.which("chromium"), shutil.which("chromium-browser")):
        if cand and Path(cand).exists():
            return cand
    return None


@contextmanager
def browser_page(url: str, *, pages: int = 1) -> Iterator[list]:
    """Yield ``pages`` Playwright pages opened on ``url`` in one headless chromium."""
    exe = chromium_path()
    if exe is None:
        pytest.skip("chromium not installed (make test installs Debian's chromium when run as root)")
    sync_api = pytest.importorskip("playwright.sync_api")
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=exe, args=CHROMIUM_FLAGS)
        try:
            context = browser.new_context(viewport=VIEWPORT)
            yield [open_page(context, url) for _ in range(pages)]
        finally:
            browser.close()


ACTION_TIMEOUT_MS = 120_000


def open_page(context, url: str):
    """A new page of ``context`` on ``url``, once viser's canvas is there.

    Actions get 120 s, not Playwright's 30 s: software WebGL on CI's two cores, shared with the app's
    loop, can draw under one frame a second, and each click waits for a few frames (actionability)."""
    page = context.new_page()
    page.set_default_timeout(ACTION_TIMEOUT_MS)
    page.goto(url, wait_until="domcontentloaded")
    page.wait_for_selector("canvas", timeout=60_000)
    return page


def wait_for(cond: Callable[[], bool], timeout: float = 60.0, interval: float = 0.1, what: str = "condition") -> None:
    """Poll ``cond`` until it holds; on timeout fail naming ``what`` and the app's state then
    (the hook of :func:`describe_failures_with`)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if cond():
            return
        time.sleep(interval)
    raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what}{_state()}")


def _state() -> str:
    return f" ({_state_hook()})" if _state_hook else ""


_state_hook: Callable[[], str] | None = None


def describe_failures_with(state: Callable[[], str] | None) -> None:
    """Name the state every later :func:`wait_for` timeout reports (a module's app fixture sets it)."""
    global _state_hook
    _state_hook = state


def app_state(app) -> str:
    """One line of the live app's state for a failure message: how far and how fast the loop ran."""
    p = app.pipeline
    return (
        f"sim t={p.time:.1f} s, real-time factor {app.real_time_factor:.2f}, drive {p.drive_mode}, nav {p.nav_status!r}, "
        f"cmd ({p.cmd.linear_x:.2f} m/s, {p.cmd.angular_z:.2f} rad/s), teleop presses {app.teleop.presses}, "
        f"clients {len(app.server.get_clients())}, loop error {app.loop_error}"
    )


def hold_key(page, key: str, until: Callable[[], bool], *, timeout: float = 60.0, what: str) -> None:
    """Keep pressing ``key`` every 0.2 s, as a held key's auto-repeat does, until ``until()`` holds.

    The teleop deadman runs on the wall clock and the loop may run well below real time on a loaded
    2-core machine, so a fixed number of presses may move the robot less than a test expects."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        page.keyboard.press(key)
        if until():
            return
        time.sleep(0.2)
    raise AssertionError(f"timed out after {timeout:.0f} s holding '{key}' for {what}{_state()}")


def screenshot(page, name: str) -> Path:
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    path = ARTIFACTS / f"{name}.png"
    page.screenshot(path=str(path))
    return path


def focus_canvas(page) -> None:
    """Click an empty spot of the 3D canvas so hotkeys are not swallowed by a form field."""
    box = page.locator("canvas").first.bounding_box()
    page.mouse.click(box["x"] + box["width"] * 0.5, box["y"] + 12)
