"""Render the README's screenshot (docs/img/app.png) from the running app in headless chromium.

Usage::

    .venv/bin/python scripts/screenshot.py [--out docs/img/app.png] [--sim-seconds 110]   # needs the [test] extra

Starts the app on a free port with the YOLO detector, drives the apartment tour for ``--sim-seconds``
of simulated time, then opens the page in Debian's chromium (Playwright, no ``playwright install``),
switches to the top-down view and the Objects tab and saves the page.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from app.config import Config
from app.server import OcslamApp

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from browser import CHROMIUM_FLAGS, chromium_path  # noqa: E402  (the browser tests' chromium setup)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "img" / "app.png")
    ap.add_argument("--sim-seconds", type=float, default=110.0)
    ap.add_argument("--width", type=int, default=1280)
    ap.add_argument("--height", type=int, default=760)
    args = ap.parse_args()
    exe = chromium_path()
    if exe is None:
        raise SystemExit("chromium not found: sudo apt-get install chromium")
    from playwright.sync_api import sync_playwright

    app = OcslamApp(Config.load(None, ["server.port=0", "sim.speed=20"])).start()
    try:
        app.submit(lambda p: p.follow_route("tour"))
        while app.pipeline.sim.time < args.sim_seconds:
            time.sleep(0.5)
        app.submit(lambda p: p.stop_autonomy("screenshot"))
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=exe, args=CHROMIUM_FLAGS)
            page = browser.new_page(viewport={"width": args.width, "height": args.height})
            page.goto(app.url, wait_until="domcontentloaded")
            page.get_by_role("button", name="Top-down view").wait_for(timeout=60_000)
            page.get_by_role("button", name="Top-down view").click()
            page.get_by_role("tab", name="Objects").click()
            time.sleep(4.0)  # scene and panel updates
            for close in page.locator(".mantine-Notification-closeButton").all():
                close.click()  # the "software WebGL" notice of a GPU-less browser
            time.sleep(1.0)
            args.out.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(args.out))
            browser.close()
    finally:
        app.stop()
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
