"""The pybullet simulation: LIDAR, camera intrinsics, segmentation, drive, collisions, ground truth."""

from __future__ import annotations

import math

import numpy as np
import pytest
from shapely.geometry import Point, Polygon

from app.config import Config
from app.ocslam.messages import Twist
from app.ocslam.se2 import Pose2
from app.sim_world import SimWorld, pose3
from app.world.format import load_world
from app.world.types import Wall, World, WorldObject


def box_room(half: float = 3.0, thickness: float = 0.2, objects: list[WorldObject] | None = None, start: Pose2 | None = None) -> World:
    """A square room; wall inner faces at ±(half − thickness/2)."""
    h = half
    corners = [(-h, -h), (h, -h), (h, h), (-h, h)]
    walls = [Wall(corners[k], corners[(k + 1) % 4], thickness, 2.4) for k in range(4)]
    return World(name="box", walls=walls, objects=objects or [], start=start or Pose2())


def quiet_config(**over) -> Config:
    cfg = Config()
    cfg.encoders.slip_std = 0.0
    cfg.encoders.noise_std_rad = 0.0
    cfg.encoders.resolution_rad = 0.0
    cfg.camera.noise_std = 0.0
    for k, v in over.items():
        cfg.set(k, v)
    return cfg


@pytest.fixture(scope="module")
def apartment_sim():
    sim = SimWorld(load_world("assets/worlds/apartment.yaml"), Config(), seed=1)
    yield sim
    sim.close()


def test_lidar_range_to_known_wall():
    sim = SimWorld(box_room(), Config(), seed=3)
    try:
        scan = sim.scan()
        assert len(scan.ranges) == 360 and scan.angle_min == pytest.approx(-math.pi)
        assert scan.angle_increment == pytest.approx(math.radians(1.0))
        x_scan = sim.robot_model.T_base_scan[0, 3]  # the LIDAR sits behind the axle
        sigma = Config().lidar.noise_std_m
        inner = 3.0 - 0.1
        ahead = scan.ranges[180]  # angle 0
        assert abs(ahead - (inner - x_scan)) < 3 * sigma
        behind = scan.ranges[0]  # angle -π
        assert abs(behind - (inner + x_scan)) < 3 * sigma
        left = scan.ranges[270]  # angle +π/2
        assert abs(left - inner) < 3 * sigma
        assert scan.stamp == sim.time
    finally:
        sim.close()


def test_lidar_no_return_is_inf_and_noise_statistics():
    cfg = Config()
    cfg.lidar.range_max_m = 2.0  # walls at 2.9 m: out of range everywhere
    sim = SimWorld(box_room(), cfg, seed=0)
    try:
        assert np.all(np.isposinf(sim.scan().ranges))
    finally:
        sim.close()
    cfg = Config()
    sim = SimWorld(box_room(), cfg, seed=0)
    try:
        r = np.array([sim.scan().ranges[180] for _ in range(200)])
        assert abs(r.std() - cfg.lidar.noise_std_m) < 0.003
        assert abs(r.mean() - (2.9 - sim.robot_model.T_base_scan[0, 3])) < 0.003
    finally:
        sim.close()


def test_camera_K_matches_projection_of_a_known_point():
    ball = WorldObject("ball", "play_ball", 2.0, 0.35, 0.0)
    sim = SimWorld(box_room(objects=[ball]), quiet_config(), seed=0)
    try:
        frame = sim.render_camera(320, 240, segmentation=True, depth=True)
        K = frame.info.K
        assert K[0, 0] == pytest.approx(160 / math.tan(1.04 / 2))
        mask = frame.segmentation == 0
        assert mask.sum() > 50
        rows, cols = np.nonzero(mask)
        # the ball's centre in the optical frame, projected with K
        T_world_cam = sim.T_world_base3() @ sim.robot_model.T_base_camera_optical
        X = np.linalg.inv(T_world_cam) @ np.array([2.0, 0.35, 0.11, 1.0])
        uvw = K @ X[:3]
        u, v = uvw[0] / uvw[2], uvw[1] / uvw[2]
        # pixel (i, j) covers [j, j+1) × [i, i+1): its centre is (j + 0.5, i + 0.5)
        assert abs(cols.mean() + 0.5 - u) < 1.0
        assert abs(rows.mean() + 0.5 - v) < 1.0
        # depth at the ball's centre pixel: distance to its near surface along optical z
        d = frame.depth[int(v), int(u)]
        assert abs(d - (X[2] - 0.11)) < 0.02
    finally:
        sim.close()


def test_segmentation_ids_match_ground_truth(apartment_sim):
    sim = apartment_sim
    truth = {o.id: o for o in sim.ground_truth_objects()}
    seen_total = set()
    for pose in (Pose2(-0.75, -2.2, -1.9), Pose2(-4.5, -4.6, -2.4), Pose2(-7.5, -3.5, 2.2), Pose2(-4.6, -1.8, 2.6)):
        frame = sim.render_view(pose, width=160, height=120, depth=True)
        K_inv = np.linalg.inv(frame.info.K)
        ids = set(np.unique(frame.segmentation)) - {-1}
        assert ids <= set(truth)
        seen_total |= ids
        for k in ids:
            rows, cols = np.nonzero(frame.segmentation == k)
            pix = np.stack([cols + 0.5, rows + 0.5, np.ones(len(rows))])
            rays = K_inv @ pix
            pts = rays * frame.depth[rows, cols][None, :]
            world = (frame.T_world_camera @ np.vstack([pts, np.ones(len(rows))]))[:3].T
            poly = Polygon(truth[k].footprint).buffer(0.05)
            inside = np.mean([poly.contains(Point(x, y)) for x, y in world[:, :2]])
            assert inside > 0.97, f"object {k} ({truth[k].label}): only {inside:.0%} of its pixels fall in its footprint"
            assert world[:, 2].min() > truth[k].z_min - 0.05 and world[:, 2].max() < truth[k].z_max + 0.05
    assert len(seen_total) >= 6


def test_ground_truth_footprints_contain_positions(apartment_sim):
    objs = apartment_sim.ground_truth_objects()
    assert len(objs) == 14 and {o.label for o in objs} >= {"table", "dog", "duck", "door"}
    for o in objs:
        poly = Polygon(o.footprint)
        assert poly.is_valid and poly.exterior.is_ccw
        assert poly.contains(Point(o.pose.x, o.pose.y)), o.name
        assert 0.0 <= o.z_min < o.z_max
    legged = {o.label for o in objs if o.legged}
    assert {"table", "dog", "person"} <= legged
    duck = next(o for o in objs if o.label == "duck")
    assert duck.z_max < sim_lidar_height(apartment_sim)
    walls = [o for o in apartment_sim.ground_truth_obstacles() if o.kind == "wall"]
    assert len(walls) >= 5


def sim_lidar_height(sim: SimWorld) -> float:
    return float(sim.robot_model.T_base_scan[2, 3])


def test_drive_straight_moves_v_t_and_encoders_agree():
    cfg = Config()  # default slip and encoder noise
    sim = SimWorld(box_room(half=5.0, start=Pose2(-3.0, 0.0, 0.0)), cfg, seed=5)
    try:
        e0 = sim.read_encoders()
        sim.set_cmd_vel(Twist(0.2, 0.0))
        sim.step(int(round(10.0 / sim.dt)))
        assert sim.time == pytest.approx(10.0)
        p = sim.true_pose()
        tau = cfg.sim.motor_time_constant_s
        expected = 0.2 * (10.0 - tau)
        assert abs(p.x - (-3.0 + expected)) < 0.03 * expected
        assert abs(p.y) < 0.1 and abs(p.yaw) < 0.05
        e1 = sim.read_encoders()
        r = sim.robot_model.wheel_radius_m
        enc_dist = ((e1.left_rad - e0.left_rad) + (e1.right_rad - e0.right_rad)) / 2 * r
        assert abs(enc_dist - (p.x + 3.0)) < 0.03 * expected
        assert e1.stamp == pytest.approx(10.0)
        assert sim.collisions == 0 and not sim.in_collision()
    finally:
        sim.close()


def test_seed_mode_turns_2_2_times_faster():
    for mode, factor in (("correct", 1.0), ("seed", 2 * 0.178 / 0.160)):
        cfg = quiet_config(**{"robot.odometry_mode": mode, "sim.motor_time_constant_s": 0.0})
        sim = SimWorld(box_room(), cfg, seed=0)
        try:
            sim.set_cmd_vel(Twist(0.0, 0.5))
            sim.step(100)
            assert sim.true_pose().yaw == pytest.approx(0.5 * factor, rel=1e-6)
        finally:
            sim.close()


def test_robot_cannot_pass_through_a_wall():
    sim = SimWorld(box_room(half=2.0), quiet_config(), seed=0)
    try:
        sim.set_cmd_vel(Twist(0.22, 0.0))
        sim.step(int(20.0 / sim.dt))  # 4.4 m of wheel travel toward a wall 1.9 m away
        p = sim.true_pose()
        inner = 2.0 - 0.1
        assert p.x < inner - sim.robot_radius + 1e-3
        assert p.x > inner - sim.robot_radius - 0.01  # it stops at the wall, not before
        assert sim.in_collision() and sim.collisions == 1
        # the wheels kept turning (slip against the wall): encoders overestimate the travel
        e = sim.read_encoders()
        assert e.left_rad * sim.robot_model.wheel_radius_m > 4.0
        # it can turn in place and drive away
        sim.set_cmd_vel(Twist(0.0, 1.0))
        sim.step(int(math.pi / sim.dt))
        sim.set_cmd_vel(Twist(0.2, 0.0))
        sim.step(100)
        assert not sim.in_collision() and sim.true_pose().x < p.x - 0.1
    finally:
        sim.close()


def test_deterministic_for_a_seed_and_reset():
    world = box_room()

    def run(seed: int):
        sim = SimWorld(world, Config(), seed=seed)
        try:
            sim.set_cmd_vel(Twist(0.15, 0.4))
            sim.step(300)
            return sim.true_pose(), sim.read_encoders(), sim.scan().ranges.copy()
        finally:
            sim.close()

    a, b, c = run(4), run(4), run(5)
    assert a[0] == b[0] and a[1] == b[1] and np.array_equal(a[2], b[2])
    assert a[0] != c[0]
    sim = SimWorld(world, Config(), seed=4)
    try:
        sim.set_cmd_vel(Twist(0.15, 0.4))
        sim.step(50)
        sim.reset()
        assert sim.time == 0.0 and sim.true_pose() == world.start
    finally:
        sim.close()


def test_encoders_quantised_and_noisy():
    cfg = Config()
    cfg.encoders.noise_std_rad = 0.0
    cfg.encoders.resolution_rad = 0.01
    sim = SimWorld(box_room(), cfg, seed=0)
    try:
        sim.set_cmd_vel(Twist(0.1, 0.0))
        sim.step(37)
        e = sim.read_encoders()
        assert e.left_rad / 0.01 == pytest.approx(round(e.left_rad / 0.01), abs=1e-9)
        assert abs(e.left_rad - sim.wheel_angles[0]) <= 0.005 + 1e-12
    finally:
        sim.close()


def test_render_camera_default_size_and_render_width():
    cfg = quiet_config()
    cfg.camera.render_width = 160
    sim = SimWorld(box_room(), cfg, seed=0)
    try:
        f = sim.render_camera()
        assert f.image.data.shape == (120, 160, 3) and f.image.data.dtype == np.uint8
        assert f.info.width == 160 and f.info.K[0, 2] == 80.0
        assert f.depth is None and f.segmentation is None
        v = sim.render_view(Pose2(0, 0, 0), width=64, height=48, pitch_rad=0.3, camera_z=0.5)
        assert v.segmentation.shape == (48, 64) and v.segmentation.dtype == np.int32
        # pitched down 0.3 rad: the optical axis points below the horizon
        assert v.T_world_camera[2, 2] == pytest.approx(-math.sin(0.3))
        assert v.T_world_camera[2, 3] == pytest.approx(0.5)
    finally:
        sim.close()


def test_pose3_matches_pose2():
    T = Pose2(1.0, -2.0, 0.7)
    M = pose3(T, 0.3)
    q = M @ np.array([0.5, 0.25, 0.0, 1.0])
    assert np.allclose(q[:2], T.transform_points(np.array([[0.5, 0.25]]))[0]) and q[2] == pytest.approx(0.3)


def test_pybullet_robot_links_agree_with_the_robot_model():
    import pybullet as p

    sim = SimWorld(box_room(), quiet_config(), seed=0)
    try:
        sim.set_robot_pose(Pose2(1.2, -0.4, 0.7))
        sim.render_camera(32, 24)  # syncs the robot's visual pose
        cid, body = sim.client, sim.robot_body
        index = {p.getJointInfo(body, j, physicsClientId=cid)[12].decode(): j for j in range(p.getNumJoints(body, physicsClientId=cid))}
        for link, T in (("base_scan", sim.robot_model.T_base_scan), ("camera_optical_frame", sim.robot_model.T_base_camera_optical)):
            pos = p.getLinkState(body, index[link], physicsClientId=cid)[4]
            assert np.allclose(pos, (sim.T_world_base3() @ T)[:3, 3], atol=1e-6), link
        # the robot itself is invisible to the LIDAR
        scan = sim.scan()
        assert np.all(scan.ranges[np.isfinite(scan.ranges)] > 0.5)
    finally:
        sim.close()


def test_arc_is_integrated_exactly():
    cfg = quiet_config(**{"sim.motor_time_constant_s": 0.0})
    sim = SimWorld(box_room(half=4.0), cfg, seed=0)
    try:
        sim.set_cmd_vel(Twist(0.1, 0.5))
        sim.step(200)  # 2 s: θ = 1 rad on a circle of radius v/ω = 0.2 m
        p = sim.true_pose()
        assert p.yaw == pytest.approx(1.0, abs=1e-9)
        assert p.x == pytest.approx(0.2 * math.sin(1.0), abs=1e-9)
        assert p.y == pytest.approx(0.2 * (1 - math.cos(1.0)), abs=1e-9)
        # encoders measure exactly the commanded wheel rotation (no slip, no noise)
        e = sim.read_encoders()
        r, sep = sim.robot_model.wheel_radius_m, sim.robot_model.wheel_separation_m
        assert e.left_rad == pytest.approx((0.1 - 0.5 * sep / 2) / r * 2.0, rel=1e-9)
        assert e.right_rad == pytest.approx((0.1 + 0.5 * sep / 2) / r * 2.0, rel=1e-9)
    finally:
        sim.close()


def test_apartment_tour_is_collision_free_and_sees_every_object():
    """Like the paper's teleoperated run: driving the 'tour' brings all 14 objects into the camera."""
    from app.bench.sim import PurePursuit

    world = load_world("assets/worlds/apartment.yaml")
    sim = SimWorld(world, quiet_config(), seed=0)
    try:
        ctrl = PurePursuit(world.route("tour"))
        best: dict[int, int] = {}
        k = 0
        while not ctrl.done and sim.time < 300:
            if k % 5 == 0:
                p = sim.true_pose()
                sim.set_cmd_vel(Twist(*ctrl.command(p.x, p.y, p.yaw)))
            sim.step()
            k += 1
            if k % 100 == 0:
                seg = sim.render_camera(160, 120, segmentation=True).segmentation
                ids, counts = np.unique(seg[seg >= 0], return_counts=True)
                for i, c in zip(ids, counts):
                    best[int(i)] = max(best.get(int(i), 0), int(c))
        assert ctrl.done and sim.collisions == 0
        assert sim.true_pose().distance(world.start) < 1.0  # a loop: back near the start
        missing = {world.object_name(i): best.get(i, 0) for i in range(len(world.objects)) if best.get(i, 0) < 30}
        assert not missing, f"objects never seen well on the tour (max pixels at 160×120): {missing}"
    finally:
        sim.close()


# ---------------------------------------------------------------------------------------------
# the renderer: EGL where it loads, TinyRenderer otherwise
# ---------------------------------------------------------------------------------------------
def _boxes(seg: np.ndarray, min_pixels: int = 40) -> dict[int, tuple[int, int, int, int]]:
    out = {}
    for i in np.unique(seg):
        ys, xs = np.nonzero(seg == i)
        if i >= 0 and len(xs) >= min_pixels:
            out[int(i)] = (int(xs.min()), int(ys.min()), int(xs.max()), int(ys.max()))
    return out


def test_forced_tiny_renderer_is_used_and_reported():
    cfg = quiet_config(**{"sim.renderer": "tiny"})
    with SimWorld(box_room(), cfg, seed=0) as sim:
        assert sim.renderer == "tiny" and "TinyRenderer" in sim.renderer_note
        f = sim.render_camera(64, 48)
        assert f.image.data.shape == (48, 64, 3) and f.image.data.std() > 0


def test_a_failed_egl_load_falls_back_to_tiny_with_a_message(monkeypatch, caplog):
    """An EGL plugin that does not load (here: a shared library that is no pybullet plugin) is found by
    the probe in a child process; auto falls back to TinyRenderer and says why, egl refuses."""
    import _ctypes
    import logging

    from app import sim_world

    monkeypatch.setenv(sim_world.EGL_PLUGIN_ENV, _ctypes.__file__)
    monkeypatch.delenv(sim_world.EGL_PROBE_ENV, raising=False)
    monkeypatch.setattr(sim_world.resolve_renderer, "_warned", False, raising=False)
    with caplog.at_level(logging.WARNING, logger="app.sim.renderer"):
        with SimWorld(box_room(), quiet_config(**{"sim.renderer": "auto"}), seed=0) as sim:
            assert sim.renderer == "tiny"
            assert "fallback" in sim.renderer_note and "EGL probe exited" in sim.renderer_note
            assert sim.render_camera(64, 48).image.data.std() > 0
    assert any("using TinyRenderer" in r.getMessage() and "apt-get install" in r.getMessage() for r in caplog.records)
    with pytest.raises(sim_world.RendererError, match="does not load"):
        SimWorld(box_room(), quiet_config(**{"sim.renderer": "egl"}), seed=0)
    monkeypatch.setenv(sim_world.EGL_PLUGIN_ENV, "/nonexistent/eglRenderer.so")
    ok, why = sim_world.probe_egl()
    assert not ok and "does not exist" in why
    with pytest.raises(sim_world.RendererError, match="unknown renderer"):
        sim_world.resolve_renderer("vulkan")


def test_egl_and_tiny_renders_agree_in_segmentation_and_boxes():
    """Same scene, same camera: the object ids seen and their boxes agree within a few pixels
    (shading differs: EGL lights with its own model)."""
    from app.sim_world import probe_egl

    ok, why = probe_egl()
    if not ok:
        pytest.skip(f"EGL cannot load here: {why}")
    world = load_world("assets/worlds/apartment.yaml")
    cfg = quiet_config()
    poses = [world.start, world.start @ Pose2(1.5, 0.3, -0.8), world.start @ Pose2(0.5, 0.0, 0.6)]
    with SimWorld(world, cfg, seed=0, renderer="tiny") as tiny, SimWorld(world, cfg, seed=0, renderer="egl") as egl:
        assert egl.renderer == "egl" and "EGL" in egl.renderer_note
        n_objects = 0
        for T in poses:
            a = tiny.render_view(T, width=320, height=240, segmentation=True, depth=True)
            b = egl.render_view(T, width=320, height=240, segmentation=True, depth=True)
            assert b.image.data.shape == a.image.data.shape and b.image.data.dtype == np.uint8
            assert np.mean(a.segmentation == b.segmentation) > 0.98
            ba, bb = _boxes(a.segmentation), _boxes(b.segmentation)
            assert set(ba) == set(bb)
            for i in ba:
                assert np.max(np.abs(np.subtract(ba[i], bb[i]))) <= 4, (i, ba[i], bb[i])
            n_objects += len(ba)
            assert np.median(np.abs(a.depth - b.depth)) < 0.03
        assert n_objects >= 5


def test_egl_draws_each_scale_of_a_shared_mesh():
    """The EGL renderer caches meshes by file name: a table's legs (its top's mesh at another scale)
    must still be drawn as legs, under the top, as TinyRenderer draws them."""
    from app.sim_world import probe_egl

    if not probe_egl()[0]:
        pytest.skip("EGL cannot load here")
    table = WorldObject(label="table", model="table", x=1.6, y=0.0, yaw=0.0)
    world = box_room(objects=[table])
    cfg = quiet_config()
    with SimWorld(world, cfg, seed=0, renderer="tiny") as tiny, SimWorld(world, cfg, seed=0, renderer="egl") as egl:
        a = tiny.render_view(Pose2(0, 0, 0), width=160, height=120, segmentation=True).segmentation
        b = egl.render_view(Pose2(0, 0, 0), width=160, height=120, segmentation=True).segmentation
    assert np.count_nonzero(a == 0) > 200
    assert np.mean((a == 0) == (b == 0)) > 0.99


@pytest.mark.parametrize("renderer", ["tiny", "egl"])
def test_cached_graphics_flag_leaves_the_images_unchanged(monkeypatch, renderer):
    """Bodies created with ``URDF_ENABLE_CACHED_GRAPHICS_SHAPES`` (:func:`~app.world.models.bodies.body_flags`)
    render the same colours, depths and segmentation ids, pixel for pixel, as bodies created without it (it
    skips the DIRECT server's GUI conversion only). The apartment has every primitive kind (boxes,
    cylinders, spheres, capsules) and meshes, each part in its own colour."""
    from app.sim import building
    from app.sim_world import probe_egl
    from app.world.models import bodies

    if renderer == "egl" and not probe_egl()[0]:
        pytest.skip("EGL cannot load here")
    world = load_world("assets/worlds/apartment.yaml")
    poses = [world.start, world.start @ Pose2(1.5, 0.3, -0.8), world.start @ Pose2(2.5, -0.4, 2.4)]

    def frames() -> list:
        with SimWorld(world, quiet_config(), seed=0, renderer=renderer) as sim:
            return [sim.render_view(T, width=160, height=120, segmentation=True, depth=True) for T in poses]

    cached = frames()
    monkeypatch.setattr(bodies, "body_flags", lambda p: 0)
    monkeypatch.setattr(building, "body_flags", lambda p: 0)
    plain = frames()
    seen = set()
    for a, b in zip(cached, plain):
        assert np.array_equal(a.image.data, b.image.data)
        assert np.array_equal(a.segmentation, b.segmentation) and np.array_equal(a.depth, b.depth)
        seen |= set(np.unique(a.segmentation).tolist())
    assert len(seen - {-1}) >= 4  # several objects in view: the comparison covers their parts


@pytest.mark.parametrize("world_name", ["apartment", "random_1003"])
def test_planar_lidar_agrees_with_pybullet_ray_tests(world_name):
    """The 2D cast against the collision shapes' cross-section at the LIDAR height (boxes, mesh hulls,
    cylinders, tilted parts) gives pybullet's 3D ray-test ranges: the same returns, within millimetres."""
    from app.world.generator import random_world

    world = load_world("assets/worlds/apartment.yaml") if world_name == "apartment" else random_world(1003)
    cfg = quiet_config(**{"lidar.noise_std_m": 0.0, "sim.renderer": "tiny"})
    ref_cfg = quiet_config(**{"lidar.noise_std_m": 0.0, "sim.renderer": "tiny", "lidar.caster": "pybullet"})
    rng = np.random.default_rng(5)
    with SimWorld(world, cfg, seed=0) as fast, SimWorld(world, ref_cfg, seed=0) as ref:
        xmin, ymin, xmax, ymax = world.bounds()
        diffs, n = [], 0
        while n < 8:
            x, y = rng.uniform(xmin, xmax), rng.uniform(ymin, ymax)
            if not ref.pose_free(x, y):
                continue
            n += 1
            T = Pose2(x, y, rng.uniform(-math.pi, math.pi))
            fast.set_robot_pose(T)
            ref.set_robot_pose(T)
            a, b = fast.scan().ranges, ref.scan().ranges
            fin = np.isfinite(a) & np.isfinite(b)
            same_kind = (np.isposinf(a) == np.isposinf(b)) & (np.isneginf(a) == np.isneginf(b))
            assert same_kind.mean() > 0.99
            diffs.append(np.abs(a[fin] - b[fin]))
        d = np.concatenate(diffs)
        assert len(d) > 1000
        assert np.median(d) < 1e-4 and np.percentile(d, 98) < 0.005 and np.mean(d > 0.05) < 0.005
