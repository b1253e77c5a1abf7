"""``ocslam bench sim``: the simulator alone — time per physics step, per LIDAR scan, per camera frame
at 640×480 and 320×240, and the real-time factor of a headless tour.

The tour drives the world's route with a simple pure-pursuit controller on the true pose (this bench
measures the simulator, not navigation), reading the encoders at ``encoders.rate_hz`` and the LIDAR at
``lidar.rate_hz``; a second pass adds the camera at ``camera.rate_hz`` at its render size. It also reports
how far the wheel odometry drifted over the tour (the realism of the slip model).
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from app.bench.common import print_json, table
from app.commands.run import add_config_arguments, config_from_args


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_config_arguments(p)
    p.add_argument("--route", default=None, help="route of the tour (default: sim.route)")
    p.add_argument("--frames", type=int, default=20, help="camera frames per resolution")
    p.add_argument("--scans", type=int, default=100, help="LIDAR scans timed")
    p.add_argument("--steps", type=int, default=3000, help="physics steps timed")
    p.add_argument("--max-duration", type=float, default=600.0, help="tour time limit (sim seconds)")
    p.add_argument("--skip-camera-tour", action="store_true", help="skip the second tour with the camera on")
    p.add_argument("--renderer", choices=("auto", "egl", "tiny"), default=None, help="camera renderer (default: sim.renderer)")
    p.add_argument("--lidar-caster", choices=("planar", "pybullet"), default=None, help="LIDAR ray caster (default: lidar.caster)")
    p.add_argument("--json", action="store_true")


class PurePursuit:
    """Drives a waypoint polyline segment by segment: turn in place toward the next waypoint, then
    drive with a proportional heading correction (little corner cutting, so validated routes stay clear)."""

    def __init__(self, waypoints: np.ndarray, *, v: float = 0.2, reach: float = 0.1, turn_in_place_rad: float = 0.35) -> None:
        self.path = np.asarray(waypoints, dtype=np.float64).reshape(-1, 2)
        self.v, self.reach, self.turn = v, reach, turn_in_place_rad
        self.i = 0  # index of the waypoint we are heading to
        self.done = len(self.path) == 0

    def command(self, x: float, y: float, yaw: float) -> tuple[float, float]:
        from app.ocslam.se2 import wrap_angle

        while not self.done and float(np.hypot(*(self.path[self.i] - (x, y)))) < self.reach:
            self.i += 1
            self.done = self.i >= len(self.path)
        if self.done:
            return 0.0, 0.0
        tx, ty = self.path[self.i]
        alpha = float(wrap_angle(math.atan2(ty - y, tx - x) - yaw))
        if abs(alpha) > self.turn:
            return 0.0, math.copysign(1.5, alpha)
        dist = float(np.hypot(tx - x, ty - y))
        return min(self.v, 0.6 * dist + 0.05), max(-1.5, min(1.5, 3.0 * alpha))


def tour(cfg, world, route: str, *, camera: bool, max_duration: float) -> dict:
    from app.ocslam.messages import Twist
    from app.ocslam.odometry import DiffDriveOdometry
    from app.sim_world import SimWorld

    sim = SimWorld(world, cfg, seed=cfg.sim.seed)
    try:
        ctrl = PurePursuit(world.route(route), v=min(0.2, cfg.robot.max_linear_mps))
        odom = DiffDriveOdometry(cfg.robot)
        odom.update(sim.read_encoders())
        start = sim.true_pose()
        dt = sim.dt
        every_enc = max(1, int(round(1.0 / (cfg.encoders.rate_hz * dt))))
        every_scan = max(1, int(round(1.0 / (cfg.lidar.rate_hz * dt))))
        every_cam = max(1, int(round(1.0 / (cfg.camera.rate_hz * dt))))
        every_ctrl = max(1, int(round(0.05 / dt)))
        n_scan = n_cam = 0
        errs = []
        k = 0
        t0 = time.perf_counter()
        while not ctrl.done and sim.time < max_duration:
            if k % every_ctrl == 0:
                p = sim.true_pose()
                v, w = ctrl.command(p.x, p.y, p.yaw)
                sim.set_cmd_vel(Twist(v, w))
            sim.step()
            k += 1
            if k % every_enc == 0:
                odom.update(sim.read_encoders())
            if k % every_scan == 0:
                sim.scan()
                n_scan += 1
                # odometry error against ground truth, both relative to the start pose
                truth = start.between(sim.true_pose())
                errs.append(truth.distance(odom.T_odom_base))
            if camera and (k + every_cam // 2) % every_cam == 0:
                sim.render_camera()
                n_cam += 1
        wall = time.perf_counter() - t0
        truth = start.between(sim.true_pose())
        err = truth.distance(odom.T_odom_base)
        from app.ocslam.se2 import wrap_angle

        return {
            "completed": ctrl.done,
            "sim_time_s": round(sim.time, 2),
            "wall_time_s": round(wall, 3),
            "real_time_factor": round(sim.time / wall, 1),
            "distance_m": round(sim.distance_m, 2),
            "collisions": sim.collisions,
            "scans": n_scan,
            "frames": n_cam,
            "render_size": list(sim.camera_size()) if camera else None,
            "odom_final_error_m": round(err, 3),
            "odom_rms_error_m": round(float(np.sqrt(np.mean(np.square(errs)))) if errs else 0.0, 3),
            "odom_final_heading_error_deg": round(math.degrees(abs(float(wrap_angle(truth.yaw - odom.T_odom_base.yaw)))), 2),
            "odom_drift_pct": round(100.0 * err / max(sim.distance_m, 1e-9), 2),
        }
    finally:
        sim.close()


def measure(cfg, *, route: str | None, frames: int, scans: int, steps: int, max_duration: float, camera_tour: bool = True) -> dict:
    from app.config import resolve_path
    from app.ocslam.messages import Twist
    from app.sim_world import SimWorld
    from app.world.format import load_world

    world = load_world(resolve_path(cfg.sim.world))
    route = route or cfg.sim.route
    t0 = time.perf_counter()
    sim = SimWorld(world, cfg, seed=cfg.sim.seed)
    build_s = time.perf_counter() - t0
    try:
        # physics: driving in an arc (collision probe every step)
        sim.set_cmd_vel(Twist(0.2, 0.3))
        sim.step(10)
        t0 = time.perf_counter()
        sim.step(steps)
        step_ms = (time.perf_counter() - t0) / steps * 1e3
        sim.reset()
        scan_t = []
        for _ in range(scans):
            t0 = time.perf_counter()
            sim.scan()
            scan_t.append(time.perf_counter() - t0)
        cam = {}
        for w, h in ((640, 480), (320, 240), (224, 168)):
            ts, ts_seg = [], []
            for _ in range(frames):
                t0 = time.perf_counter()
                sim.render_camera(w, h)
                ts.append(time.perf_counter() - t0)
            for _ in range(max(3, frames // 4)):
                t0 = time.perf_counter()
                sim.render_camera(w, h, depth=True, segmentation=True)
                ts_seg.append(time.perf_counter() - t0)
            cam[f"{w}x{h}"] = {"median_ms": round(float(np.median(ts)) * 1e3, 2),
                               "with_depth_and_segmentation_ms": round(float(np.median(ts_seg)) * 1e3, 2)}
    finally:
        sim.close()
    return {
        "world": world.name,
        "renderer": sim.renderer,
        "renderer_note": sim.renderer_note,
        "lidar_caster": cfg.lidar.caster,
        "bodies_build_s": round(build_s, 3),
        "physics_dt_s": cfg.sim.physics_dt_s,
        "step_ms": round(step_ms, 4),
        "scan_ms": round(float(np.median(scan_t)) * 1e3, 3),
        "camera_ms": cam,
        "tour": tour(cfg, world, route, camera=False, max_duration=max_duration),
        "tour_with_camera": tour(cfg, world, route, camera=True, max_duration=max_duration) if camera_tour else None,
    }


def run(args: argparse.Namespace) -> int:
    cfg = config_from_args(args)
    if args.renderer is not None:
        cfg.set("sim.renderer", args.renderer)
    if args.lidar_caster is not None:
        cfg.set("lidar.caster", args.lidar_caster)
    res = measure(cfg, route=args.route, frames=args.frames, scans=args.scans, steps=args.steps, max_duration=args.max_duration,
                  camera_tour=not args.skip_camera_tour)
    if args.json:
        print_json(res)
        return 0
    rows = [
        ("physics step (drive + collision probe)", f"{res['step_ms']:.4f} ms", f"dt {res['physics_dt_s']} s"),
        ("LIDAR scan (360 rays)", f"{res['scan_ms']:.3f} ms", res["lidar_caster"]),
    ]
    for size, c in res["camera_ms"].items():
        rows.append((f"camera {size}", f"{c['median_ms']:.1f} ms", f"+depth+seg {c['with_depth_and_segmentation_ms']:.1f} ms"))
    table(["stage", "time", "note"], rows, title=f"ocslam bench sim — world '{res['world']}' (built in {res['bodies_build_s']} s), {res['renderer_note']}")
    print()
    cam_size = "x".join(map(str, res["tour_with_camera"]["render_size"])) if res["tour_with_camera"] else "-"
    trows = []
    for name, t in (("encoders + LIDAR", res["tour"]), ("encoders + LIDAR + camera", res["tour_with_camera"])):
        if t is None:
            continue
        trows.append((name, t["sim_time_s"], t["wall_time_s"], f"×{t['real_time_factor']}", t["distance_m"], t["collisions"],
                      t["odom_final_error_m"], f"{t['odom_drift_pct']} %", t["odom_final_heading_error_deg"]))
    table(["headless tour", "sim s", "wall s", "real-time factor", "distance m", "collisions", "odom error m", "drift", "heading err °"],
          trows, title=f"tour '{args.route or cfg.sim.route}' (waypoint follower on the true pose; camera at {cam_size})")
    return 0
