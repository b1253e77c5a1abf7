"""The replay web app: a bag played through the core in the browser, with a timeline.

``ocslam replay BAG`` (without ``--headless``) starts a hardened viser server (``app.ui.security``) showing
the map, the SLAM trajectory and pose graph, the robot, the current scan and the object map as the replay
advances, and a **Replay** panel:

- **Play / Pause**; **Rate** 0.25×–8× of bag time; **Step** to the next scan;
- **Seek**: a slider over the bag's duration; the core restarts from the nearest snapshot of its state
  at or before the target (``replay.snapshot_period_s``) and runs forward, not from the start;
- **Loop**: at the end, start again from the beginning.

:class:`ReplayPlayer` is the timeline itself (no GUI), driven by a thread; :class:`ReplayApp` binds it to
the scene and the panel.
"""

from __future__ import annotations

import contextlib
import io
import logging
import threading
import time
from typing import Any

import numpy as np

log = logging.getLogger(__name__)

RATES = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0)


class ReplayPlayer:
    """Play/pause/rate/step/seek/loop over a :class:`app.ros2.replay.ReplayCore` (thread-safe)."""

    def __init__(self, core: Any, rate: float = 1.0, loop: bool = False) -> None:
        self.core = core
        self.rate = float(rate)
        self.loop = bool(loop)
        self.playing = False
        self.lock = threading.RLock()
        self._anchor: tuple[float, float] | None = None  # (wall time, bag time) when play started
        self.seeks = 0

    @property
    def t0(self) -> float:
        return self.core.t_start

    @property
    def duration(self) -> float:
        return max(self.core.t_end - self.core.t_start, 0.0)

    @property
    def position(self) -> float:
        """Seconds from the bag's start."""
        return max(self.core.time - self.t0, 0.0)

    def set_rate(self, rate: float) -> None:
        with self.lock:
            if not (0.25 <= rate <= 8.0):
                raise ValueError(f"rate must be in 0.25–8, got {rate}")
            self.rate = float(rate)
            self._anchor = None

    def play(self) -> None:
        with self.lock:
            if self.core.done and self.loop:
                self.seek(0.0)
            self.playing = True
            self._anchor = None

    def pause(self) -> None:
        with self.lock:
            self.playing = False

    def step(self) -> bool:
        """Pause and advance to the next scan (False at the end)."""
        with self.lock:
            self.playing = False
            return self.core.step_scan()

    def seek(self, position_s: float) -> None:
        """Go to ``position_s`` seconds from the start (from the nearest earlier snapshot)."""
        with self.lock:
            self.core.seek(self.t0 + min(max(position_s, 0.0), self.duration))
            self._anchor = None
            self.seeks += 1

    def tick(self, now: float | None = None) -> int:
        """Advance playback to the current wall time; returns the events processed."""
        now = time.perf_counter() if now is None else now
        with self.lock:
            if not self.playing:
                return 0
            if self._anchor is None:
                self._anchor = (now, self.core.time)
            target = self._anchor[1] + (now - self._anchor[0]) * self.rate
            n = self.core.run_until(target)
            if self.core.done:
                if self.loop:
                    self.seek(0.0)
                else:
                    self.playing = False
            return n


class ReplayApp:
    """The viser scene and the Replay panel around a :class:`ReplayPlayer`."""

    def __init__(self, core: Any, *, host: str = "127.0.0.1", port: int = 8080, rate: float = 1.0) -> None:
        from app.ui.security import create_server

        with contextlib.redirect_stdout(io.StringIO()):
            self.server, _ = create_server(host, port)
        self.core = core
        self.player = ReplayPlayer(core, rate=rate)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._last_map = -1e9
        self._build_scene()
        self._build_panel()

    @property
    def url(self) -> str:
        return f"http://{self.server.get_host()}:{self.server.get_port()}"

    # -- scene -------------------------------------------------------------------------------------
    def _build_scene(self) -> None:
        s = self.server.scene
        self.grid_image = s.add_image("/replay/map", np.full((2, 2, 3), 205, np.uint8), 0.1, 0.1, format="png",
                                      position=(0, 0, 0.005))
        self.robot = s.add_frame("/replay/base_footprint", axes_length=0.25, axes_radius=0.01)
        self.scan_points = s.add_point_cloud("/replay/scan", np.zeros((1, 3), np.float32), colors=(230, 40, 40),
                                             point_size=0.03)
        self.traj = s.add_line_segments("/replay/trajectory", np.zeros((1, 2, 3)), colors=(30, 90, 230), thickness=0.02)
        self.objects: dict[int, Any] = {}

    def _update_scene(self, with_map: bool) -> None:
        from app.ui.colors import CLASS_COLORS, grid_to_rgb
        from app.ui.scene import polyline_segments, wxyz

        core = self.core
        T = core.T_map_base
        self.robot.position = (float(T.x), float(T.y), 0.0)
        self.robot.wxyz = wxyz(T.yaw)
        scan = core.state.last_scan
        if scan is not None:
            p = scan.points()
            if len(p):
                pts = (T @ core.T_base_scan).transform_points(p)
                self.scan_points.points = np.column_stack([pts, np.full(len(pts), 0.15)]).astype(np.float32)
        if not (with_map and core.cfg.slam.enabled):
            return
        grid = core.slam.occupancy_grid()
        if grid.width and grid.height:
            w, h = grid.width * grid.resolution, grid.height * grid.resolution
            c = grid.origin.transform_points(np.array([[w / 2, h / 2]]))[0]
            self.grid_image.image = grid_to_rgb(grid.data)
            self.grid_image.render_width, self.grid_image.render_height = w, h
            self.grid_image.position = (float(c[0]), float(c[1]), 0.005)
            self.grid_image.wxyz = wxyz(grid.origin.yaw)
        _, traj = core.slam.trajectory()
        if len(traj) > 1:
            self.traj.points = polyline_segments(traj[:: max(1, len(traj) // 2000), :2], 0.02)
        thr = core.cfg.consciousness.presence_threshold
        shown = {o.id: o for o in core.objects_in_map() if o.presence >= thr}
        for i in list(self.objects):
            if i not in shown:
                self.objects.pop(i).remove()
        for i, o in shown.items():
            h = o.size_z if o.size_z > 0 else 0.3
            color = CLASS_COLORS.get(o.label, (200, 200, 200))
            if i in self.objects:
                self.objects[i].remove()
            self.objects[i] = self.server.scene.add_box(
                f"/replay/objects/{i}", color=color, dimensions=(max(o.size_x, 0.05), max(o.size_y, 0.05), h),
                position=(float(o.pose.x), float(o.pose.y), h / 2), wxyz=wxyz(o.pose.yaw), opacity=0.6)

    # -- panel -------------------------------------------------------------------------------------
    def _build_panel(self) -> None:
        g = self.server.gui
        p = self.player
        with g.add_folder("Replay"):
            self.status = g.add_markdown(self._status_text())
            self.play_button = g.add_button("Play")
            self.step_button = g.add_button("Step (next scan)")
            self.rate = g.add_dropdown("Rate", tuple(f"{r:g}x" for r in RATES), initial_value=f"{p.rate:g}x")
            self.seek_slider = g.add_slider("Seek (s)", min=0.0, max=max(round(p.duration, 1), 0.1), step=0.1,
                                            initial_value=0.0)
            self.loop = g.add_checkbox("Loop", initial_value=p.loop)

        @self.play_button.on_click
        def _(_e) -> None:
            if p.playing:
                p.pause()
            else:
                p.play()
            self._refresh()

        @self.step_button.on_click
        def _(_e) -> None:
            p.step()
            self._refresh(with_map=True)

        @self.rate.on_update
        def _(_e) -> None:
            p.set_rate(float(self.rate.value.rstrip("x")))

        @self.seek_slider.on_update
        def _(_e) -> None:
            if abs(self.seek_slider.value - p.position) > 0.15:  # a user's move, not our own update
                p.seek(float(self.seek_slider.value))
                self._refresh(with_map=True)

        @self.loop.on_update
        def _(_e) -> None:
            p.loop = bool(self.loop.value)

    def _status_text(self) -> str:
        p = self.player
        c = self.core.state.counters
        return (f"**{'playing' if p.playing else 'paused'}** {p.position:.1f} / {p.duration:.1f} s at {p.rate:g}×  \n"
                f"scans {c.scans}, frames fused {c.fused_frames}, objects "
                f"{sum(o.presence >= self.core.cfg.consciousness.presence_threshold for o in self.core.objects_in_map())}")

    def _refresh(self, with_map: bool = False) -> None:
        p = self.player
        with p.lock:
            self._update_scene(with_map or time.perf_counter() - self._last_map > 1.0)
            if with_map or time.perf_counter() - self._last_map > 1.0:
                self._last_map = time.perf_counter()
            self.status.content = self._status_text()
            self.play_button.label = "Pause" if p.playing else "Play"
            self.seek_slider.value = round(p.position, 1)

    # -- running -----------------------------------------------------------------------------------
    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                n = self.player.tick()
                if n or self.player.playing:
                    self._refresh()
            except Exception:
                log.exception("replay tick failed")
                self.player.pause()
            time.sleep(0.05)

    def start(self) -> ReplayApp:
        self._refresh(with_map=True)
        self._thread = threading.Thread(target=self._run, name="ocslam-replay", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        with contextlib.redirect_stdout(io.StringIO()):
            self.server.stop()


def serve_replay(core: Any, *, rate: float = 1.0) -> int:
    """``ocslam replay BAG``: the web app, blocking until Ctrl-C."""
    cfg = core.cfg
    app = ReplayApp(core, host=cfg.server.host, port=cfg.server.port, rate=min(max(rate, 0.25), 8.0)).start()
    print(f"OCSLAM replay of {core.bag.path}: open {app.url} (Ctrl-C stops)", flush=True)
    try:
        while True:
            time.sleep(0.5)
    except KeyboardInterrupt:
        pass
    finally:
        app.stop()
    return 0
