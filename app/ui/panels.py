"""GUI panels: Drive (camera, teleop, autonomy), Tune (every live config field), Objects, Metrics,
Layers and Session. Callbacks run on viser's thread pool: they issue the app's commands
(:class:`~app.ui.commands.GuiCommands`: ``app.submit`` queues work for the loop) or flip plain flags;
they never touch pybullet or the estimators directly, and never import the server.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import viser
import viser.uplot

from app.config import PROJECT_ROOT, ConfigError
from app.ui.commands import GuiCommands
from app.ui.scene import LAYERS, SceneLayers

log = logging.getLogger(__name__)

#: hotkey → teleop key ("space" and "k" stop). WASD/QE and the arrows belong to viser's camera.
HOTKEYS: tuple[tuple[str, str, str], ...] = (
    ("I", "i", "forward"),
    (",", ",", "backward"),
    ("J", "j", "turn left"),
    ("L", "l", "turn right"),
    ("U", "u", "forward arc left"),
    ("O", "o", "forward arc right"),
    ("M", "m", "backward arc right"),
    (".", ".", "backward arc left"),
    ("K", "k", "stop"),
    ("space", "space", "stop"),
)

HOLD_BUTTONS: tuple[tuple[str, str], ...] = (("Forward", "i"), ("Left", "j"), ("Stop", "k"), ("Right", "l"), ("Back", ","))


def notify_clients(client: Any, server: viser.ViserServer, title: str, body: str, color: str = "red") -> None:
    """A notification to ``client`` (None: every client of ``server``); a client that left is skipped."""
    targets = [client] if client is not None else list(server.get_clients().values())
    for c in targets:
        try:
            c.add_notification(title, body, auto_close_seconds=5.0, color=color)
        except Exception:
            pass


MAX_OFFERED_WORLDS = 300


def offered_worlds(current: str, roots: tuple[Path, ...]) -> dict[str, Path]:
    """The World dropdown: option label → real path. The running world (chosen by whoever started the
    server) first, then every ``*.yaml`` under ``roots`` (sub-folders too) whose real path stays inside
    its root (a symlink pointing out is not offered). Labels are relative to the project root where
    possible (``assets/worlds/apartment.yaml``)."""
    from app.config import resolve_path

    out: dict[str, Path] = {current: resolve_path(current).resolve()}
    for root in roots:
        if not root.is_dir():
            continue
        for f in sorted(root.rglob("*.yaml"))[:MAX_OFFERED_WORLDS]:
            real = f.resolve()
            if not real.is_file() or not real.is_relative_to(root):
                continue
            try:
                label = str(f.relative_to(PROJECT_ROOT))
            except ValueError:
                label = str(Path(root.name) / f.relative_to(root))
            out.setdefault(label, real)
    return out


def detections_overlay(rgb: np.ndarray, detections, width: int) -> np.ndarray:
    """The camera image with the YOLO boxes (class colour, label, confidence), resized to ``width``."""
    try:
        from app.ocslam.detector import draw_detections

        img = draw_detections(rgb, detections) if detections is not None else rgb
    except Exception:
        img = rgb
    h = int(round(img.shape[0] * width / img.shape[1]))
    return cv2.resize(img, (width, h), interpolation=cv2.INTER_AREA)


class Panels:
    """Every panel of one viser ``server`` (shared by all its clients); ``layers``: its scene layers
    (the Layers tab toggles them); ``app``: what the panels' buttons ask for and what they show."""

    def __init__(self, server: viser.ViserServer, layers: SceneLayers, app: GuiCommands) -> None:
        self.app = app
        self.server = server
        self.layers = layers
        gui = self.server.gui
        gui.configure_theme(control_width="medium", show_share_button=False, dark_mode=False)
        self.config_handles: dict[str, Any] = {}
        self.layer_handles: dict[str, Any] = {}
        self.object_buttons: dict[int, Any] = {}
        self._last_image_stamp = -1.0
        self._history: deque[tuple[float, ...]] = deque(maxlen=600)
        self._last_hist = 0.0
        self.follow_robot = False
        tabs = gui.add_tab_group()
        with tabs.add_tab("Drive", icon=viser.Icon.STEERING_WHEEL):
            self._build_drive()
        with tabs.add_tab("Tune", icon=viser.Icon.ADJUSTMENTS):
            self._build_tune()
        with tabs.add_tab("Objects", icon=viser.Icon.BOX):
            self._build_objects()
        with tabs.add_tab("Metrics", icon=viser.Icon.CHART_LINE):
            self._build_metrics()
        with tabs.add_tab("Layers", icon=viser.Icon.STACK_2):
            self._build_layers()
        with tabs.add_tab("Session", icon=viser.Icon.DEVICE_FLOPPY):
            self._build_session()
        self._build_hotkeys()

    # ------------------------------------------------------------------------------------------
    # Drive
    # ------------------------------------------------------------------------------------------
    def _build_drive(self) -> None:
        gui = self.server.gui
        app = self.app
        self.status = gui.add_markdown("starting…")
        self.camera_image = gui.add_image(np.zeros((120, 160, 3), np.uint8), label="Camera (YOLO boxes)", format="jpeg",
                                          jpeg_quality=80)
        with gui.add_folder("Teleop (keys: i , j l u o m . k/space)"):
            for label, key in HOLD_BUTTONS:
                b = gui.add_button(label, hint=f"hold to drive (key '{key}')", color="red" if key == "k" else None)
                b.on_click(lambda ev, k=key: app.teleop_key(k))
                b.on_hold(lambda ev, k=key: app.teleop_key(k), callback_hz=10.0)
            self.speed_readout = gui.add_markdown("")
            self._config_control("ui.teleop_linear_mps", label="linear speed (m/s)")
            self._config_control("ui.teleop_angular_rps", label="turn rate (rad/s)")
        with gui.add_folder("Simulation"):
            self.pause_button = gui.add_button("Pause", icon=viser.Icon.PLAYER_PAUSE)
            self.pause_button.on_click(lambda ev: self.app.toggle_pause())
            b = gui.add_button("Step", icon=viser.Icon.PLAYER_TRACK_NEXT, hint="advance one LIDAR period while paused")
            b.on_click(lambda ev: self.app.single_step())
            self._config_control("sim.speed", label="sim speed (× real time)")
            b = gui.add_button("Reset world", icon=viser.Icon.REFRESH, hint="restart the world; the map is lost")
            b.on_click(lambda ev: self.app.reset_world())
            #: dropdown option → the world file it loads (the only worlds "Load world" can name)
            self.world_paths: dict[str, Path] = offered_worlds(self.app.cfg.sim.world, self.app.worlds_roots)
            current = self.app.cfg.sim.world
            self.world_choice = gui.add_dropdown("World", tuple(self.world_paths), initial_value=current)
            b = gui.add_button("Load world", hint="worlds from " + ", ".join(f"{r.name}/" for r in self.app.worlds_roots))
            b.on_click(lambda ev: self.app.load_world(self.world_choice.value, client=ev.client))
        with gui.add_folder("Autonomy"):
            routes = tuple(self.app.pipeline.world.routes) or ("(none)",)
            self.route_choice = gui.add_dropdown("Route", routes, initial_value=routes[0])
            b = gui.add_button("Follow route", icon=viser.Icon.ROUTE)
            b.on_click(lambda ev: self.app.submit(lambda p: p.follow_route(self.route_choice.value), client=ev.client))
            b = gui.add_button("Explore", icon=viser.Icon.COMPASS, hint="frontier exploration until nothing is left")
            b.on_click(lambda ev: self.app.submit(lambda p: p.explore(), client=ev.client))
            b = gui.add_button("Stop autonomy", icon=viser.Icon.HAND_STOP)
            b.on_click(lambda ev: self.app.submit(lambda p: p.stop_autonomy("stopped by user"), client=ev.client))
            gui.add_markdown("Click on the floor to send the robot there (A* on the SLAM grid).")
        with gui.add_folder("View"):
            b = gui.add_button("Top-down view", icon=viser.Icon.MAP)
            b.on_click(lambda ev: self.app.top_down_view(ev.client))
            self.follow_box = gui.add_checkbox("Follow robot", False)
            self.follow_box.on_update(lambda ev: setattr(self, "follow_robot", bool(self.follow_box.value)))

    def _build_hotkeys(self) -> None:
        gui = self.server.gui
        for hotkey, key, what in HOTKEYS:
            cmd = gui.add_command(f"Teleop: {what}", description=f"key '{key}' (teleop_twist_keyboard)", hotkey=hotkey)  # type: ignore[arg-type]
            cmd.on_trigger(lambda ev, k=key: self.app.teleop_key(k))

    # ------------------------------------------------------------------------------------------
    # Tune: every live config field, bound to the same Config the CLI and YAML use
    # ------------------------------------------------------------------------------------------
    def _config_control(self, path: str, *, label: str | None = None) -> Any:
        gui = self.server.gui
        cfg = self.app.cfg
        _, f = cfg.field_info(path)
        meta = f.metadata
        value = cfg.get(path)
        label = label or path.split(".", 1)[1]
        hint = (meta.get("help") or "") + (f" [{meta['unit']}]" if meta.get("unit") else "")
        if meta.get("choices"):
            h = gui.add_dropdown(label, tuple(str(c) for c in meta["choices"]), initial_value=str(value), hint=hint)
        elif isinstance(value, bool):
            h = gui.add_checkbox(label, value, hint=hint)
        elif isinstance(value, (int, float)) and meta.get("min") is not None and meta.get("max") is not None:
            step = meta.get("step") or (1 if isinstance(value, int) else (meta["max"] - meta["min"]) / 100)
            h = gui.add_slider(label, min=meta["min"], max=meta["max"], step=step, initial_value=value, hint=hint)
        elif isinstance(value, (int, float)):
            h = gui.add_number(label, value, hint=hint)
        else:
            h = gui.add_text(label, str(value), hint=hint)
        h.on_update(lambda ev, p=path, hh=h: self._on_config_change(p, hh, ev))
        self.config_handles.setdefault(path, []).append(h)
        return h

    def _on_config_change(self, path: str, handle: Any, event: Any) -> None:
        value = handle.value
        try:
            self.app.cfg.field_info(path)
            _, f = self.app.cfg.field_info(path)
            from app.ocslam.config import coerce_value

            coerce_value(path.split(".")[0], f, value)  # refuse now, with a notification
        except ConfigError as e:
            notify_clients(getattr(event, "client", None), self.server, "Value refused", str(e))
            old = self.app.cfg.get(path)
            if handle.value != old:
                handle.value = old if not isinstance(old, bool) else bool(old)
            return
        self.app.set_config(path, value, client=getattr(event, "client", None))

    def sync_config_handles(self) -> None:
        """Show the config's current values (after Reset or Load config)."""
        for path, handles in self.config_handles.items():
            v = self.app.cfg.get(path)
            for h in handles:
                try:
                    shown = str(v) if isinstance(h, viser.GuiDropdownHandle) else v
                    if h.value != shown:
                        h.value = shown
                except Exception:
                    pass

    def _build_tune(self) -> None:
        gui = self.server.gui
        sections: dict[str, list[str]] = {}
        for path, f, _ in self.app.cfg.iter_fields():
            if f.metadata.get("live") and not path.startswith("ui.teleop") and path != "sim.speed":
                sections.setdefault(path.split(".")[0], []).append(path)
        for section in ("consciousness", "detector", "slam", "lidar", "encoders", "camera", "robot", "sim", "ui"):
            if section not in sections:
                continue
            with gui.add_folder(section.capitalize(), expand_by_default=section in ("consciousness", "detector")):
                for path in sections[section]:
                    self._config_control(path)
        with gui.add_folder("Config file"):
            self.config_path = gui.add_text("Save to", "runs/ocslam-config.yaml")
            b = gui.add_button("Save config", icon=viser.Icon.DEVICE_FLOPPY)
            b.on_click(lambda ev: self.app.save_config(self.config_path.value, client=ev.client))
            b = gui.add_button("Reset to defaults", icon=viser.Icon.RESTORE)
            b.on_click(lambda ev: self.app.reset_config(client=ev.client))

    # ------------------------------------------------------------------------------------------
    # Objects
    # ------------------------------------------------------------------------------------------
    def _build_objects(self) -> None:
        gui = self.server.gui
        self.objects_summary = gui.add_markdown("No objects yet.")
        self.objects_table = gui.add_html("")
        gui.add_markdown("Click an object to focus the 3D view on it:")
        self.objects_folder = gui.add_folder("Focus", expand_by_default=True)

    def _update_objects(self) -> None:
        p = self.app.pipeline
        thr = p.cfg.consciousness.presence_threshold
        objs = sorted(p.consciousness.objects, key=lambda o: (-o.presence, o.label))
        shown = [o for o in objs if o.presence >= thr]
        self.objects_summary.content = (
            f"**{len(shown)}** objects at presence ≥ {thr:.0%} (tracking {len(objs)}; mode `{p.cfg.consciousness.mode}`)"
        )
        rows = []
        for o in objs[:60]:
            T = self.layers._object_pose_map(o)
            style = "" if o.presence >= thr else " style='opacity:0.45'"
            rows.append(
                f"<tr{style}><td>{o.label}</td><td>{T.x:.2f}, {T.y:.2f}</td><td>{o.size_x:.2f}×{o.size_y:.2f}</td>"
                f"<td>{o.presence * 100:.0f}%</td><td>{o.frames_seen}</td><td>{o.source.replace('_', ' ')}</td></tr>"
            )
        self.objects_table.content = (
            "<table style='font-size:0.8em;width:100%'><tr><th>class</th><th>x, y (map)</th><th>size</th>"
            "<th>p</th><th>frames</th><th>source</th></tr>" + "".join(rows) + "</table>"
        )
        ids = {o.id for o in shown}
        for oid in list(self.object_buttons):
            if oid not in ids:
                self.object_buttons.pop(oid).remove()
        with self.objects_folder:
            for o in shown:
                label = f"{o.label} #{o.id}"
                if o.id not in self.object_buttons:
                    b = self.server.gui.add_button(label, icon=viser.Icon.FOCUS_2)
                    b.on_click(lambda ev, oid=o.id: self.app.focus_object(oid, ev.client))
                    self.object_buttons[o.id] = b

    # ------------------------------------------------------------------------------------------
    # Metrics
    # ------------------------------------------------------------------------------------------
    def _build_metrics(self) -> None:
        gui = self.server.gui
        self.metrics_md = gui.add_markdown("")
        self.truth_md = gui.add_markdown("")
        x = np.zeros(1)
        self.rtf_plot = gui.add_uplot(
            (x, x),
            (viser.uplot.Series(label="t (s)"), viser.uplot.Series(label="real-time factor", stroke="blue", width=2)),
            title="Real-time factor", scales={"x": {"time": False}}, aspect=2.0,
        )
        self.quality_plot = gui.add_uplot(
            (x, x, x, x),
            (
                viser.uplot.Series(label="t (s)"),
                viser.uplot.Series(label="precision", stroke="green", width=2),
                viser.uplot.Series(label="recall", stroke="orange", width=2),
                viser.uplot.Series(label="SLAM ATE (m)", stroke="purple", width=2),
            ),
            title="Objects and SLAM vs ground truth", scales={"x": {"time": False}}, aspect=2.0,
        )

    # ------------------------------------------------------------------------------------------
    # Layers
    # ------------------------------------------------------------------------------------------
    def _build_layers(self) -> None:
        gui = self.server.gui
        with gui.add_folder("Layers"):
            for key, label, visible in LAYERS:
                h = gui.add_checkbox(label, visible)
                h.on_update(lambda ev, k=key, hh=h: self.layers.set_visible(k, bool(hh.value)))
                self.layer_handles[key] = h

    # ------------------------------------------------------------------------------------------
    # Session
    # ------------------------------------------------------------------------------------------
    def _build_session(self) -> None:
        gui = self.server.gui
        self.session_path = gui.add_text("Run directory", "runs/session")
        b = gui.add_button("Save session", icon=viser.Icon.DEVICE_FLOPPY,
                           hint="config, map (YAML+PGM), objects.json, trajectory, summary, .viser recording")
        b.on_click(lambda ev: self.app.save_session(self.session_path.value, client=ev.client))
        b = gui.add_button("Load session", icon=viser.Icon.FOLDER_OPEN, hint="restore map, objects and pose graph")
        b.on_click(lambda ev: self.app.load_session(self.session_path.value, client=ev.client))
        self.record_path = gui.add_text("Bag folder", "runs/recording",
                                        hint="a new folder under the runs directory (never overwritten)")
        self.record_toggle = gui.add_checkbox("Record (rosbag2 MCAP)", False,
                                              hint="/scan /odom /tf /camera /yolo_boxes /objects /map …: docs/ros2.md")
        self.record_toggle.on_update(self._on_record_toggle)
        self.map_path = gui.add_text("Map file", "runs/map.yaml")
        b = gui.add_button("Export map", icon=viser.Icon.DOWNLOAD, hint="map_server / Nav2 YAML + PGM")
        b.on_click(lambda ev: self.app.export_map(self.map_path.value, client=ev.client))
        self.session_status = gui.add_markdown("")

    def _on_record_toggle(self, ev: Any) -> None:
        if self._setting_record:
            return
        if self.record_toggle.value:
            self.app.start_recording(self.record_path.value, client=ev.client)
        else:
            self.app.stop_recording(client=ev.client)

    def set_recording_state(self, on: bool) -> None:
        """Show the recorder's state on the toggle without acting on it."""
        if self.record_toggle.value != on:
            self._setting_record = True
            try:
                self.record_toggle.value = on
            finally:
                self._setting_record = False

    _setting_record = False

    # ------------------------------------------------------------------------------------------
    # periodic update (loop thread)
    # ------------------------------------------------------------------------------------------
    def update(self) -> None:
        app = self.app
        p = app.pipeline
        T = p.T_map_base
        odo = p.T_odom_base
        rtf = app.real_time_factor
        mode = p.drive_mode + (f" — {p.nav_status}" if p.nav_status else "")
        paused = " **(paused)**" if app.paused else ""
        self.status.content = (
            f"sim **{p.time:.1f} s** · ×{rtf:.1f} real time{paused}  \n"
            f"map: x {T.x:+.2f} y {T.y:+.2f} θ {math.degrees(T.yaw):+.0f}°  \n"
            f"odom: x {odo.x:+.2f} y {odo.y:+.2f} θ {math.degrees(odo.yaw):+.0f}°  \n"
            f"drive: {mode}"
            + (f"  \n⚠ detector: {p.detector_error}" if p.detector_error else "")
        )
        self.speed_readout.content = f"cmd_vel: v {p.cmd.linear_x:+.2f} m/s · ω {p.cmd.angular_z:+.2f} rad/s"
        self.pause_button.label = "Resume" if app.paused else "Pause"
        if p.fusion.image is not None and p.fusion.stamp != self._last_image_stamp:
            self._last_image_stamp = p.fusion.stamp
            self.camera_image.image = detections_overlay(p.fusion.image.data, p.fusion.detections, p.cfg.ui.camera_width)
        elif p.fusion.image is None and p.detector is None and p.time - getattr(self, "_last_raw_cam", -9) > 1.0:
            self._last_raw_cam = p.time
            try:
                frame = p.sim.render_camera(160, 120)
                self.camera_image.image = frame.image.data
            except Exception:
                pass
        self._update_objects()
        self._update_metrics()

    def _update_metrics(self) -> None:
        app = self.app
        p = app.pipeline
        stages = p.timer.recent_ms
        lines = [f"real-time factor ×{app.real_time_factor:.1f} (target ×{p.cfg.sim.speed:.1f})", "", "| stage | ms per call |", "|---|---|"]
        lines += [f"| {k} | {v:.2f} |" for k, v in stages.items()]
        c = p.counters
        lines += ["", f"scans {c.scans} · images {c.images} · detections {c.detections} · skipped {sum(c.skipped_frames.values())}"
                  f" · errors {sum(c.errors.values())}"]
        m = p.metrics()
        w, h = m["camera_size"]
        lines += [f"camera {w}×{h} · {m['renderer_note']}"]
        sm = p.slam.metrics()
        lines += [f"loop closures: {sm['slam_loops_accepted']} accepted · {sm['slam_loops_rejected']} rejected"
                  f" · {sm['slam_loops_pending']} pending"]
        self.metrics_md.content = "\n".join(lines)
        now = p.time
        if now - self._last_hist < 1.0:
            return
        self._last_hist = now
        prec = rec = ate = float("nan")
        if self.layers.is_visible("truth"):
            try:
                rep = p.object_report()
                prec, rec = rep.precision_strict, rep.recall
                sm = p.slam_metrics()
                ate = sm.get("slam_ate_rmse_m", float("nan"))
                self.truth_md.content = (
                    f"**vs ground truth**: objects precision {prec:.0%} (lenient {rep.precision_lenient:.0%}), "
                    f"recall {rec:.0%} ({rep.tp}/{rep.in_scene}), position error {rep.pos_err_mean_m:.3f} m · "
                    f"SLAM ATE {ate:.3f} m · map precision {sm.get('map_precision', float('nan')):.2f} recall "
                    f"{sm.get('map_recall', float('nan')):.2f}"
                )
            except Exception as e:
                self.truth_md.content = f"ground truth metrics unavailable: {e}"
        else:
            self.truth_md.content = "Show the *Ground truth overlay* layer for live precision/recall and SLAM ATE."
        self._history.append((now, app.real_time_factor, prec, rec, ate))
        h = np.array(self._history, dtype=np.float64)
        self.rtf_plot.data = (h[:, 0], h[:, 1])
        self.quality_plot.data = (h[:, 0], h[:, 2], h[:, 3], h[:, 4])
