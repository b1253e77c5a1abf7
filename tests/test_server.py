"""The web server on port 0: starts, streams the scene to protocol-level clients, drives, stops cleanly."""

from __future__ import annotations

import threading
import time

import pytest

from app.bench.wsclient import FakeViserClient
from app.config import Config
from app.server import OcslamApp

#: the default renderer (auto): the server's loop thread renders the camera preview itself with TinyRenderer
#: (an EGL context belongs to the thread that made it; a render from another thread used to kill the process)
BASE = ["detector.kind=none", "server.port=0"]


def wait_for(cond, timeout=20.0, what="condition"):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if cond():
            return
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")


@pytest.fixture()
def app():
    cfg = Config.load(None, BASE)
    a = OcslamApp(cfg).start()
    try:
        yield a
    finally:
        a.stop()


def test_server_starts_on_a_free_port_and_stops_cleanly() -> None:
    before = {t.name for t in threading.enumerate()}
    cfg = Config.load(None, BASE)
    a = OcslamApp(cfg).start()
    assert a.port > 0 and a.url == f"http://127.0.0.1:{a.port}"
    assert a.server.get_host() == "127.0.0.1"
    wait_for(lambda: a.pipeline.time > 0.5, what="the sim to advance")
    a.stop()
    time.sleep(0.5)
    leftover = {t.name for t in threading.enumerate() if t.is_alive()} - before
    assert "ocslam-loop" not in leftover
    assert a.loop_error is None


def test_clients_see_the_scene_and_teleop_drives(app) -> None:
    c1 = FakeViserClient(app.port).connect()
    c2 = FakeViserClient(app.port).connect()
    try:
        wait_for(lambda: "Forward" in c1.stats.labels and "Forward" in c2.stats.labels, what="the GUI")
        wait_for(lambda: len(app.server.get_clients()) == 2, what="two clients")
        assert c1.stats.message_types.get("PointCloudMessage", 0) >= 1  # LIDAR layer
        start = app.pipeline.sim.true_pose()
        def held() -> bool:  # a held button: ~10 Hz events, the deadman keeps it moving (in wall time, so
            c2.click("Forward")  # a slow, shared CPU needs more of them)
            time.sleep(0.1)
            return app.pipeline.sim.true_pose().distance(start) > 0.1

        wait_for(held, timeout=60, what="the robot to move forward")
        moved = app.pipeline.sim.true_pose()
        dx = start.between(moved)
        assert dx.x > 0.1 and abs(dx.y) < 0.05  # forward in base_footprint (REP-103: +x)
        # a client vanishing mid-stream leaves the loop and the other client untouched
        c1.abort()
        t0, f0 = app.pipeline.time, c2.stats.frames
        wait_for(lambda: app.pipeline.time > t0 + 1.0 and c2.stats.frames > f0 + 5, what="the loop to continue")
        wait_for(lambda: len(app.server.get_clients()) == 1, what="the dropped client to be gone")
        assert app.loop_error is None
    finally:
        c1.close()
        c2.close()


def test_keyboard_teleop_bindings_and_deadman(app) -> None:
    t = app.teleop
    assert t.press("i").linear_x > 0 and t.command().angular_z == 0
    assert t.press(",").linear_x < 0
    assert t.press("j").angular_z > 0 and t.press("l").angular_z < 0
    u, o = t.press("u"), t.press("o")
    assert u.linear_x > 0 < u.angular_z and o.linear_x > 0 > o.angular_z
    m, dot = t.press("m"), t.press(".")
    assert m.linear_x < 0 > m.angular_z and dot.linear_x < 0 < dot.angular_z
    t.press("space")
    assert t.command().linear_x == 0 and not t.active


def test_deadman_expires() -> None:
    from app.ui.teleop import Teleop

    now = [0.0]
    t = Teleop(0.2, 1.0, deadman_s=0.6, clock=lambda: now[0])
    t.press("i")
    now[0] = 0.5
    assert t.command().linear_x == pytest.approx(0.2)
    now[0] = 0.61
    assert t.command().linear_x == 0.0
    t.press("w")  # not a teleop key (viser's camera owns WASD)
    assert t.command().linear_x == 0.0


def test_metrics_panel_names_the_renderer_and_the_loop_closures(app) -> None:
    wait_for(lambda: app.pipeline.time > 1.5, what="the sim to advance")
    wait_for(lambda: "loop closures:" in app.panels.metrics_md.content, what="the metrics panel")
    text = app.panels.metrics_md.content
    assert "TinyRenderer" in text and "camera " in text
    assert "accepted" in text and "rejected" in text
    assert app.pipeline.sim.renderer == "tiny" and app.loop_error is None


def test_record_toggle_writes_a_rosbag2_bag_under_the_runs_directory(tmp_path) -> None:
    """Session panel → Record: a bag folder (metadata.yaml + .mcap) that rosbags reads; an existing folder or
    a path out of the runs directory is refused and the toggle falls back off."""
    from rosbags.highlevel import AnyReader

    cfg = Config.load(None, [*BASE, f"server.runs_dir={tmp_path}"])
    (tmp_path / "taken").mkdir()
    a = OcslamApp(cfg).start()
    c = FakeViserClient(a.port).connect()
    try:
        for bad in ("taken", "../outside"):
            c.set_value("Bag folder", bad)
            wait_for(lambda bad=bad: a.panels.record_path.value == bad, what="the folder text")
            c.set_value("Record (rosbag2 MCAP)", True)
            wait_for(lambda: not a.panels.record_toggle.value and a.recorder is None, what="a refused recording")
        assert not (tmp_path.parent / "outside").exists()
        c.set_value("Bag folder", "drive")
        wait_for(lambda: a.panels.record_path.value == "drive", what="the folder text")
        c.set_value("Record (rosbag2 MCAP)", True)
        wait_for(lambda: a.recorder is not None, timeout=60, what="the recorder to start")
        t0 = a.pipeline.time
        wait_for(lambda: a.pipeline.time > t0 + 2.0, timeout=60, what="two recorded sim seconds")
        c.set_value("Record (rosbag2 MCAP)", False)
        wait_for(lambda: a.recorder is None, timeout=60, what="the bag to be finished")
        bag = tmp_path / "drive"
        assert (bag / "metadata.yaml").is_file() and list(bag.glob("*.mcap")), sorted(tmp_path.rglob("*"))
        with AnyReader([bag]) as reader:
            counts = {con.topic: con.msgcount for con in reader.connections}
        assert counts.get("/scan", 0) >= 5 and counts.get("/odom", 0) >= 5 and counts.get("/tf_static", 0) >= 1
        assert a.loop_error is None
    finally:
        c.close()
        a.stop()


def test_the_app_implements_every_gui_command(app) -> None:
    """The panels reach the server only through :class:`GuiCommands`: the app has each of its members, and
    each command takes the parameters the protocol names, of the same kind."""
    import inspect

    from app.ui.commands import GuiCommands

    names = [n for n in vars(GuiCommands) if not n.startswith("_")]
    assert {"submit", "load_world", "top_down_view", "focus_object", "save_config", "start_recording"} <= set(names)
    for n in names:
        assert hasattr(app, n), f"OcslamApp lacks {n}"
        member = vars(GuiCommands)[n]
        if isinstance(member, property):
            continue
        have = inspect.signature(getattr(app, n)).parameters
        for pname, p in inspect.signature(member).parameters.items():
            if pname != "self":
                assert pname in have and have[pname].kind == p.kind, f"OcslamApp.{n}: parameter {pname}"


def test_the_ui_package_never_imports_the_server() -> None:
    import ast
    from pathlib import Path

    import app.ui

    bad = []
    for f in sorted(Path(app.ui.__file__).parent.rglob("*.py")):
        for node in ast.walk(ast.parse(f.read_text(encoding="utf-8"))):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
            if isinstance(node, ast.ImportFrom):
                names = [node.module or ""] + [f"{node.module}.{a.name}" for a in node.names]
            if any(n == "app.server" or n.startswith("app.server.") for n in names):
                bad.append(f"{f.name}:{node.lineno}")
    assert not bad, f"app/ui imports app.server: {bad}"
