"""The viser web server and the ``ocslam`` CLI entry point.

:class:`OcslamApp` owns one :class:`~app.pipeline.Pipeline` (advanced by a single loop thread at the
configured speed), a hardened viser server (``app.ui.security``), the scene layers and the panels.
Every browser tab sees the same world; teleop from any of them drives the one robot.

Example:
    >>> app = OcslamApp(Config.load(None, ["server.port=0"]))
    >>> app.start(); print(app.url)
    >>> app.stop()
"""

from __future__ import annotations

import logging
import os
import socket
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from app.config import PROJECT_ROOT, Config, ConfigError
from app.ui.confine import PathRefused, confine_path, safe_message

log = logging.getLogger(__name__)


class OcslamApp:
    """The live app: simulation loop thread + viser server + UI. Its commands are what the panels call
    (it implements :class:`app.ui.commands.GuiCommands`)."""

    def __init__(self, cfg: Config, *, pipeline: Any = None) -> None:
        from app.pipeline import Pipeline
        from app.ui.panels import Panels
        from app.ui.scene import SceneLayers
        from app.ui.security import GuiGuard, create_server
        from app.ui.teleop import Teleop

        self.cfg = cfg
        #: the only directory GUI paths may name for sessions, maps and configs (resolved)
        self.runs_root = project_path(cfg.server.runs_dir)
        #: directories whose worlds the World dropdown offers
        self.worlds_roots = tuple(project_path(d) for d in cfg.server.worlds_dirs)
        from app.ui.security import is_loopback, new_token

        #: access token for a non-loopback host (None: loopback, or --no-token)
        self.token: str | None = (
            new_token() if cfg.server.require_token and not is_loopback(cfg.server.host) else None
        )
        # bind first: an unusable --host/--port fails fast, before the (slow) pipeline is built
        self.server, self.origin_policy = create_server(
            cfg.server.host, cfg.server.port, allow_origins=list(cfg.server.allow_origins), label="OCSLAM",
            token=self.token,
        )
        try:
            self.pipeline = pipeline if pipeline is not None else Pipeline(cfg, same_thread=False)
        except BaseException:
            self.server.stop()
            raise
        self.gui_guard = GuiGuard(self.server, on_refused=self._on_refused)
        self._world_loading = threading.Lock()  # held while a world loads (off the loop thread)
        self._pending_pipeline: Any = None  # a loaded world's pipeline waiting for the loop to swap it in
        self.teleop = Teleop(cfg.ui.teleop_linear_mps, cfg.ui.teleop_angular_rps, cfg.ui.teleop_deadman_s)
        self.pipeline.manual_cmd = self.teleop.command
        self._lock = threading.RLock()  # guards pipeline replacement (load world)
        self.paused = False
        self._step_request = False
        self.real_time_factor = 0.0
        self.ticks = 0
        self.layers = SceneLayers(self.server, self.pipeline)
        self.panels = Panels(self.server, self.layers, self)
        self._install_scene_click()
        self._set_initial_camera()
        self._stop = threading.Event()
        #: the rosbag2 recorder of the running pipeline (Session panel's Record toggle, ``run --record``)
        self.recorder: Any = None
        self.recording_path: Path | None = None
        self._thread = threading.Thread(target=self._loop, name="ocslam-loop", daemon=True)
        self.loop_error: str | None = None
        self.server.on_client_connect(self._on_connect)

    # ------------------------------------------------------------------------------------------
    @property
    def port(self) -> int:
        return int(self.server.get_port())

    @property
    def url(self) -> str:
        """The address to open (with ``/?token=…`` when a token is required)."""
        host = self.cfg.server.host
        shown = "127.0.0.1" if host in ("0.0.0.0", "::", "") else (f"[{host}]" if ":" in host else host)
        return f"http://{shown}:{self.port}" + (f"/?token={self.token}" if self.token else "")

    def start(self) -> OcslamApp:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=10)
        try:
            self.server.stop()
        finally:
            self._finish_recording(self.pipeline)
            self.pipeline.close()
        if self._world_loading.acquire(timeout=30):  # a world that finished loading after the loop stopped
            self._world_loading.release()
        pending, self._pending_pipeline = self._pending_pipeline, None
        if pending is not None:
            pending.close()

    # ------------------------------------------------------------------------------------------
    # the loop thread
    # ------------------------------------------------------------------------------------------
    def _loop(self) -> None:
        wall0, sim0 = time.perf_counter(), self.pipeline.time
        next_ui = next_map = 0.0
        rtf_wall, rtf_sim = wall0, sim0
        while not self._stop.is_set():
            try:
                now = time.perf_counter()
                p = self.pipeline
                self._apply_ui_settings()
                if self.paused and not self._step_request:
                    p.drain_commands()
                    wall0, sim0 = now, p.time
                else:
                    if self._step_request:
                        self._step_request = False
                        target = p.time + 1.0 / self.cfg.lidar.rate_hz
                        while p.time < target - 1e-9:
                            p.step()
                        wall0, sim0 = now, p.time
                    else:
                        due = sim0 + (now - wall0) * self.cfg.sim.speed
                        budget = now + 0.05  # keep the UI responsive even when the sim cannot keep up
                        while p.time < due and time.perf_counter() < budget:
                            p.step()
                        if due - p.time > 0.5:  # behind: don't try to catch up forever
                            wall0, sim0 = time.perf_counter(), p.time
                if now - rtf_wall >= 1.0:
                    self.real_time_factor = (p.time - rtf_sim) / (now - rtf_wall)
                    rtf_wall, rtf_sim = now, p.time
                if now >= next_ui:
                    with_map = now >= next_map
                    t0 = time.perf_counter()
                    self._update_ui(with_map)
                    p.timer.add("ui", time.perf_counter() - t0)
                    next_ui = now + 1.0 / self.cfg.ui.update_hz
                    if with_map:
                        next_map = now + 1.0 / self.cfg.ui.map_hz
                    self.ticks += 1
                # sleep until the next physics step is due (or a short while when paused)
                dt = self.cfg.sim.physics_dt_s / max(self.cfg.sim.speed, 1e-3)
                time.sleep(0.02 if self.paused else max(0.0, min(dt, next_ui - time.perf_counter())))
            except Exception as e:  # never let one bad tick kill the app
                log.exception("loop error")
                self.loop_error = str(e)
                self.pipeline.counters.error("loop")
                time.sleep(0.1)

    def _apply_ui_settings(self) -> None:
        ui = self.cfg.ui
        self.teleop.linear_mps = ui.teleop_linear_mps
        self.teleop.angular_rps = ui.teleop_angular_rps
        self.teleop.deadman_s = ui.teleop_deadman_s

    def _update_ui(self, with_map: bool) -> None:
        with self.server.atomic():
            self.layers.update(with_map=with_map)
            self.panels.update()
        if self.panels.follow_robot:
            T = self.pipeline.T_map_base
            for c in self.server.get_clients().values():
                try:
                    off = np.asarray(c.camera.position) - np.asarray(c.camera.look_at)
                    # viser keeps the viewing direction when the position is set: position first
                    c.camera.position = (T.x + off[0], T.y + off[1], off[2])
                    c.camera.look_at = (T.x, T.y, 0.0)
                except Exception:
                    pass

    # ------------------------------------------------------------------------------------------
    # commands (called from viser's thread pool)
    # ------------------------------------------------------------------------------------------
    def notify(self, client: Any, title: str, body: str, color: str = "blue") -> None:
        """A one-line notification (see :func:`app.ui.confine.safe_message`) to ``client`` (None: all)."""
        from app.ui.panels import notify_clients

        notify_clients(client, self.server, title, safe_message(body), color)

    def _on_refused(self, client_id: int, message: str) -> None:
        client = self.server.get_clients().get(client_id)
        if client is not None:
            self.notify(client, "Value refused", message, "red")

    def submit(self, fn: Callable[[Any], Any], *, client: Any = None, files: Callable[[], tuple[Path, ...]] = tuple,
               what: str = "Command failed") -> None:
        """Run ``fn(pipeline)`` in the loop thread; report failures to the client (never quoting ``files()``)."""

        def run(p: Any) -> None:
            try:
                fn(p)
            except Exception as e:
                log.warning("%s: %s", what, e)
                self.notify(client, what, safe_message(e, files=files()), "red")

        self.pipeline.submit(run)

    # ------------------------------------------------------------------------------------------
    # paths the GUI names
    # ------------------------------------------------------------------------------------------
    def gui_path(self, text: Any, what: str, *, suffix: str | None = None, must_exist: bool = False) -> Path:
        """``text`` from a GUI field as a real path inside :attr:`runs_root` (:class:`PathRefused` if not)."""
        path = confine_path(text, self.runs_root, what=what, must_exist=must_exist)
        if suffix is not None and path.suffix.lower() not in (suffix, ".yml" if suffix == ".yaml" else suffix):
            raise PathRefused(f"{what}: the file name must end in {suffix}")
        return path

    def _refuse(self, client: Any, title: str, e: Exception) -> None:
        log.warning("%s: %s", title, e)
        self.notify(client, title, str(e), "red")

    def teleop_key(self, key: str) -> None:
        self.teleop.press(key)

    def toggle_pause(self) -> None:
        self.paused = not self.paused

    def single_step(self) -> None:
        self.paused = True
        self._step_request = True

    def set_config(self, path: str, value: Any, *, client: Any = None) -> None:
        def apply(p: Any) -> None:
            try:
                self.cfg.set(path, value)
            except ConfigError as e:
                self.notify(client, "Value refused", str(e), "red")

        self.pipeline.submit(apply)

    def save_config(self, path: str, *, client: Any = None) -> None:
        try:
            target = self.gui_path(path, "Save config", suffix=".yaml")
        except PathRefused as e:
            return self._refuse(client, "Config not saved", e)
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            out = self.cfg.save(target)
            self.notify(client, "Config saved", f"{self._shown(out)}: run it with `ocslam run --config {out}`", "green")
        except Exception as e:
            log.warning("config not saved: %s", e)
            self.notify(client, "Config not saved", safe_message(e), "red")

    def reset_config(self, *, client: Any = None) -> None:
        def apply(p: Any) -> None:
            defaults = Config()
            for path, f, _ in defaults.iter_fields():
                if f.metadata.get("live"):
                    self.cfg.set(path, defaults.get(path))
            self.panels.sync_config_handles()
            self.notify(client, "Config reset", "Live settings restored to their defaults.", "green")

        self.pipeline.submit(apply)

    def reset_world(self) -> None:
        self.pipeline.submit(lambda p: p.reset())

    def load_world(self, choice: str, *, client: Any = None, wait: bool = False) -> None:
        """Replace the pipeline with one on the World dropdown's ``choice``.

        Only worlds the dropdown offered can be named (:attr:`Panels.world_paths`). Reading,
        validating and building the new pipeline run in a helper thread, so the loop and every
        other client go on meanwhile (an over-limit world is refused by ``app.world.validation``
        before anything heavy); only the swap runs in the loop thread. One load at a time.
        ``wait``: block until done (tests).
        """
        path = self.panels.world_paths.get(choice) if isinstance(choice, str) else None
        if path is None:
            return self._refuse(client, "World not loaded", PathRefused("World: not one of the offered worlds"))
        if not self._world_loading.acquire(blocking=False):
            self.notify(client, "World not loaded", "another world is still loading", "orange")
            return
        self.notify(client, "Loading world", self._shown(path), "blue")
        t = threading.Thread(target=self._load_world_worker, args=(choice, path, client), name="ocslam-load-world",
                             daemon=True)
        t.start()
        if wait:
            t.join()

    def _load_world_worker(self, choice: str, path: Path, client: Any) -> None:
        from app.pipeline import Pipeline
        from app.world.format import load_world

        try:
            try:
                world = load_world(path)
                new = Pipeline(self.cfg, world=world, same_thread=False)
            except Exception as e:
                log.warning("world %s not loaded: %s", path, e)
                self.notify(client, "World not loaded", f"{self._shown(path)}: {safe_message(e, files=(path,))}",
                            "red")
                return
            new.manual_cmd = self.teleop.command
            if self._stop.is_set():
                new.close()
                return
            self._pending_pipeline = new
            done = threading.Event()

            def swap(p: Any) -> None:
                try:
                    if self._pending_pipeline is not new:
                        return
                    self._pending_pipeline = None
                    self.cfg.sim.world = choice
                    old = self.pipeline
                    bag = self._finish_recording(old)
                    if bag is not None:
                        self.notify(client, "Recording stopped", f"the world changed; bag {self._shown(bag)}", "blue")
                    self.pipeline = new
                    self.layers.pipeline = new
                    self.layers.rebuild_world()
                    old.close()
                    routes = tuple(world.routes) or ("(none)",)
                    self.panels.route_choice.options = routes
                    self.panels.route_choice.value = routes[0]
                    self.notify(client, "World loaded", f"{world.name}: {len(world.objects)} objects", "green")
                finally:
                    done.set()

            self.pipeline.submit(swap)
            while not done.wait(0.1) and not self._stop.is_set():
                pass
        finally:
            self._world_loading.release()

    def export_map(self, path: str, *, client: Any = None) -> None:
        try:
            target = self.gui_path(path, "Export map", suffix=".yaml")
        except PathRefused as e:
            return self._refuse(client, "Map not exported", e)

        def apply(p: Any) -> None:
            from app.ocslam.mapio import save_map

            target.parent.mkdir(parents=True, exist_ok=True)
            out = save_map(p.slam.occupancy_grid(), target)
            self.notify(client, "Map exported", f"{self._shown(out)} (map_server YAML + PGM)", "green")

        self.submit(apply, client=client, what="Map not exported")

    def save_session(self, path: str, *, client: Any = None) -> None:
        try:
            target = self.gui_path(path, "Save session")
        except PathRefused as e:
            return self._refuse(client, "Session not saved", e)

        def apply(p: Any) -> None:
            from app.session import save_session

            out = save_session(p, target, server=self.server)
            self.panels.session_status.content = f"saved to `{self._shown(out)}` at sim {p.time:.1f} s"
            self.notify(client, "Session saved", self._shown(out), "green")

        self.submit(apply, client=client, what="Session not saved")

    def start_recording(self, path: str | Path, *, client: Any = None, confined: bool = True) -> None:
        """Record the running pipeline as a rosbag2 MCAP bag folder (``path``: a new folder under the runs
        directory when named from the GUI; ``ocslam run --record`` names any path, ``confined=False``)."""
        try:
            target = self.gui_path(path, "Record") if confined else Path(path).absolute()
            if target.exists():
                raise PathRefused(f"Record: {self._shown(target)} exists (a bag is never overwritten)")
        except PathRefused as e:
            self.panels.set_recording_state(False)
            return self._refuse(client, "Not recording", e)

        def apply(p: Any) -> None:
            from app.ros2.recorder import attach

            if self.recorder is not None:
                return
            try:
                self.recorder, self.recording_path = attach(p, target), target
            except Exception:
                self.panels.set_recording_state(False)
                raise
            self.panels.session_status.content = f"recording to `{self._shown(target)}` since sim {p.time:.1f} s"
            self.notify(client, "Recording", f"rosbag2 MCAP bag {self._shown(target)}", "green")

        self.submit(apply, client=client, what="Not recording")

    def stop_recording(self, *, client: Any = None) -> None:
        def apply(p: Any) -> None:
            bag = self._finish_recording(p)
            if bag is not None:
                self.panels.session_status.content = f"bag written to `{self._shown(bag)}` at sim {p.time:.1f} s"
                self.notify(client, "Recording stopped", f"bag {self._shown(bag)} (ros2 bag info / Foxglove)", "green")

        self.submit(apply, client=client, what="Recording not finished")

    def _finish_recording(self, pipeline: Any) -> Path | None:
        """Close the bag of ``pipeline`` if it is being recorded (idempotent); the bag's folder."""
        rec, path = self.recorder, self.recording_path
        if rec is None:
            return None
        from app.ros2.recorder import detach

        try:
            detach(pipeline, rec)
        except Exception as e:
            log.warning("recording not finished: %s", e)
        finally:
            self.recorder = self.recording_path = None  # only once the bag is complete
        self.panels.set_recording_state(False)
        return path

    def load_session(self, path: str, *, client: Any = None) -> None:
        try:
            target = self.gui_path(path, "Load session", must_exist=True)
        except PathRefused as e:
            return self._refuse(client, "Session not loaded", e)

        def files() -> tuple[Path, ...]:
            return tuple(f for f in sorted(target.glob("*"))[:50] if f.is_file()) if target.is_dir() else (target,)

        def apply(p: Any) -> None:
            from app.session_load import load_session

            load_session(p, target)
            self.layers._grid_stamp = -1.0
            self.panels.session_status.content = f"loaded `{self._shown(target)}`"
            self.notify(client, "Session loaded", f"map, objects and pose graph restored from {self._shown(target)}",
                        "green")

        self.submit(apply, client=client, files=files, what="Session not loaded")

    def _shown(self, path: Path | str) -> str:
        """``path`` as the GUI shows it: relative to the runs root's parent (``runs/session``)."""
        p = Path(path)
        for root in (self.runs_root, *self.worlds_roots):
            if p.is_relative_to(root):
                return str(Path(root.name) / p.relative_to(root))
        return p.name

    # ------------------------------------------------------------------------------------------
    # views
    # ------------------------------------------------------------------------------------------
    def _clients(self, client: Any) -> list[Any]:
        return [client] if client is not None else list(self.server.get_clients().values())

    def top_down_view(self, client: Any = None) -> None:
        c, size = self._world_bounds_map()
        for cl in self._clients(client):
            if hasattr(cl.camera, "up_direction"):
                cl.camera.up_direction = (0.0, 1.0, 0.0)
            cl.camera.position = (float(c[0]), float(c[1]) - 0.01, float(max(size, 4.0) * 1.1))
            cl.camera.look_at = (float(c[0]), float(c[1]), 0.0)

    def focus_object(self, object_id: int, client: Any = None) -> None:
        for o in self.pipeline.consciousness.objects:
            if o.id == object_id:
                T = self.layers._object_pose_map(o)
                for cl in self._clients(client):
                    cl.camera.position = (T.x - 1.2, T.y - 1.2, 1.4)
                    cl.camera.look_at = (T.x, T.y, 0.2)
                return

    def _world_bounds_map(self) -> tuple[np.ndarray, float]:
        """Centre ``(2,)`` and size of the world, in the map frame."""
        xmin, ymin, xmax, ymax = self.pipeline.world.bounds()
        corners = np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]])
        c = self.pipeline.T_map_world.transform_points(corners)
        return c.mean(axis=0), float(max(xmax - xmin, ymax - ymin))

    def _set_initial_camera(self) -> None:
        c, size = self._world_bounds_map()
        ic = self.server.initial_camera
        ic.look_at = (float(c[0]), float(c[1]), 0.0)
        ic.position = (float(c[0]) - 0.35 * size, float(c[1]) - 0.55 * size, 0.75 * size)
        ic.up = (0.0, 0.0, 1.0)

    def _on_connect(self, client: Any) -> None:
        log.info("client %s connected", client.client_id)

    def _install_scene_click(self) -> None:
        """Click-to-go: a click on the floor (z = 0 in the map frame) plans and follows an A* path."""

        @self.server.scene.on_click()
        def _(event: Any) -> None:
            try:
                o = np.asarray(event.ray_origin, dtype=float).reshape(3)
                d = np.asarray(event.ray_direction, dtype=float).reshape(3)
            except (TypeError, ValueError):
                return
            if not (np.isfinite(o).all() and np.isfinite(d).all()) or abs(d[2]) < 1e-6:
                return
            s = -o[2] / d[2]
            if s <= 0:
                return
            x, y = (o + s * d)[:2]
            grid = self.pipeline.slam.occupancy_grid()
            if grid.width and grid.height:
                rc = grid.world_to_cell(np.array([[x, y]]))[0]
                if not (0 <= rc[0] < grid.height and 0 <= rc[1] < grid.width) or grid.data[rc[0], rc[1]] < 0:
                    return  # off the known map (e.g. a click to focus the canvas): not a goal
            self.teleop.stop()
            self.submit(lambda p: p.go_to((float(x), float(y))) or self.notify(
                event.client, "No path", f"no path to ({x:.2f}, {y:.2f}) on the SLAM grid", "orange"), client=event.client)


def project_path(p: str | Path) -> Path:
    """A config directory as a real path (relative: to the project root)."""
    path = Path(p).expanduser()
    return Path(os.path.realpath(path if path.is_absolute() else PROJECT_ROOT / path))


def serve(cfg: Config, *, record: str | None = None) -> int:
    """``ocslam run``: start the web app and block until Ctrl-C. ``record``: a bag folder to record the run
    into (``""``: a new ``recording-<date>`` folder under the runs directory); the bag is finished on exit."""
    from app.ui.security import is_loopback

    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    app = OcslamApp(cfg).start()
    if record is not None:
        target = Path(record) if record else app.runs_root / time.strftime("recording-%Y%m%d-%H%M%S")
        app.panels.set_recording_state(True)
        app.start_recording(target, confined=False)
        print(f"recording a rosbag2 bag to {target}", flush=True)
    print(f"OCSLAM is running: open {app.url} in your browser (Ctrl-C stops)", flush=True)
    if not is_loopback(cfg.server.host):
        if app.token:
            print(f"Listening on {cfg.server.host}: from another machine open "
                  f"http://{socket.gethostname()}:{app.port}/?token={app.token} (the token is required; "
                  "it changes at every start)", flush=True)
        else:
            print(f"WARNING: listening on {cfg.server.host} with --no-token: anyone who can reach this machine can "
                  "drive the robot and save files under the runs directory.", flush=True)
    try:
        while True:
            time.sleep(0.5)
    except KeyboardInterrupt:
        print("stopping…", flush=True)
    finally:
        app.stop()
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Console-script entry: ``ocslam …``."""
    from app.cli import main as cli_main

    return cli_main(argv)
