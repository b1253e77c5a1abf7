"""The simulated TurtleBot3 Burger in a world: pybullet geometry, kinematic drive, sensors, ground truth.

:class:`SimWorld` is the facade of the package :mod:`app.sim`, which holds the parts, one concept per
module (measured choices, see ``ocslam bench sim``):

- **Geometry** (:mod:`app.sim.building`) lives in a private pybullet DIRECT client: one static body per
  model part, walls as boxes with their openings cut out, a floor, and the robot loaded from its URDF
  (:mod:`app.sim.robot_model`; moved kinematically).
- **Motion** (:mod:`app.sim.drive`) is kinematic, not dynamic: each fixed step the commanded wheel rates
  (``cmd_vel`` through :func:`twist_to_wheel_rates`, so ``robot.odometry_mode = "seed"`` reproduces the
  original's turn-rate bug physically) pass a first-order motor lag; the wheels turn by ``ω·dt`` (what the
  encoders measure) while the ground sees ``r·ω·(1 − slip)`` with a slowly varying per-wheel slip (and an
  optional per-run wheel-radius error). The pose integrates exactly along the arc. A step that would put
  the robot's collision cylinder (radius ``robot.footprint_radius_m``, ``sim.robot_height_m`` tall) into
  anything is refused (the robot stalls, its wheels slip), so it never passes through walls or objects.
  Deterministic for a seed; no contact dynamics to tune or to explode.
- **LIDAR** (:mod:`app.sim.lidar`): from the ``base_scan`` frame of the URDF, rays cast in 2D against the
  exact cross-section of every collision shape at the LIDAR's height (:class:`PlanarCaster`,
  ``lidar.caster = planar``; the world is static), or one pybullet ``rayTestBatch``
  (``lidar.caster = pybullet``); **camera** (:mod:`app.sim.camera`, :mod:`app.sim.renderer`): pybullet's
  EGL renderer plugin (OpenGL; Mesa's llvmpipe without a GPU) where it loads, else TinyRenderer
  (``sim.renderer``: ``auto | egl | tiny``), from ``camera_optical_frame``, with depth and a segmentation
  of ground-truth object ids. The EGL plugin is first probed in a child process (a broken EGL stack
  exits the process that loads it), once per process tree. Rendering in a separate process:
  :mod:`app.sim.render_worker`. A process that builds one world after another (a dataset worker)
  lends each a :class:`RenderClient`, which loads the EGL plugin once.

Every message is stamped with sim time (``SimWorld.time``). All noise comes from seeded
``numpy.random.Generator`` streams (one per source). Ground truth (:meth:`true_pose`, :meth:`ground_truth_objects`,
...; :mod:`app.sim.ground_truth`) is for evaluation and overlays only.

Example:
    >>> sim = SimWorld(load_world("assets/worlds/apartment.yaml"), Config())
    >>> sim.set_cmd_vel(Twist(0.2, 0.0)); sim.step(100)                 # 1 s forward
    >>> scan, frame = sim.scan(), sim.render_camera(320, 240, segmentation=True)
    >>> sim.close()
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from app.config import Config
from app.ocslam.messages import (
    CameraInfo,
    GroundTruthObject,
    GroundTruthObstacle,
    Image,
    LaserScan,
    Twist,
    WheelEncoders,
)
from app.ocslam.odometry import twist_to_wheel_rates
from app.ocslam.se2 import Pose2, wrap_angle
from app.sim.building import FAR_AWAY, build_bodies
from app.sim.camera import Camera, CameraFrame, PixelNoise, camera_size
from app.sim.drive import CollisionProbe, KinematicDrive
from app.sim.egl_shadow import shadow_map_switch
from app.sim.ground_truth import ground_truth_objects, ground_truth_obstacles
from app.sim.lidar import Lidar, PlanarCaster
from app.sim.renderer import (
    EGL_PLUGIN_ENV,
    EGL_PROBE_ENV,
    RENDERER_ENV,
    RENDERERS,
    RenderClient,
    RendererError,
    egl_mesh_alias,
    egl_plugin_path,
    probe_egl,
    resolve_renderer,
)
from app.sim.robot_model import RobotModel
from app.world.models.catalogue import get_model
from app.world.types import World

# the parts' public names stay importable from here (the simulator's one entry point)
__all__ = [
    "CameraFrame", "EGL_PLUGIN_ENV", "EGL_PROBE_ENV", "PlanarCaster", "RENDERERS", "RENDERER_ENV", "RenderClient",
    "RendererError", "SimWorld", "pose3", "probe_egl", "resolve_renderer",
]

log = logging.getLogger(__name__)


def pose3(T: Pose2, z: float = 0.0) -> NDArray[np.float64]:
    """``(4, 4)`` homogeneous matrix of a planar pose at height ``z``."""
    c, s = math.cos(T.yaw), math.sin(T.yaw)
    M = np.eye(4)
    M[:2, :2] = [[c, -s], [s, c]]
    M[:3, 3] = (T.x, T.y, z)
    return M


class SimWorld:
    """A world, the robot and its sensors in a private pybullet client (see the module docstring)."""

    def __init__(
        self,
        world: World,
        config: Config,
        *,
        seed: int | None = None,
        renderer: str | None = None,
        client: RenderClient | None = None,
    ) -> None:
        """``renderer``: ``auto | egl | tiny`` (default ``config.sim.renderer``); the one in use is
        :attr:`renderer` (``"egl"`` or ``"tiny"``) with a human-readable :attr:`renderer_note`.
        ``client``: a :class:`RenderClient` to build in (its renderer is used; it stays open after
        :meth:`close`, for the next world); by default the world opens and closes its own."""
        import pybullet as p

        self._p = p
        self.world = world
        self.config = config
        self.seed = int(config.sim.seed if seed is None else seed)
        self.dt = float(config.sim.physics_dt_s)
        self.robot_model = RobotModel.load()
        requested = renderer if renderer is not None else getattr(config.sim, "renderer", "auto")
        self._owns_client = client is None
        self._render_client = RenderClient(requested) if client is None else client
        self.renderer, self.renderer_note = self._render_client.renderer, self._render_client.note
        self.client: int = self._render_client.lend()
        #: the EGL plugin's OpenGL context is current on the thread that loaded it only: a render from any
        #: other thread crashes the process (even with ER_TINY_RENDERER), so it is refused instead
        self._gl_thread: int | None = self._render_client.gl_thread
        try:
            bodies = build_bodies(p, self.client, world, self.robot_model, config,
                                  mesh_file=egl_mesh_alias if self.renderer == "egl" else None)
        except Exception:
            self.close()
            raise
        self.floor_body = bodies.floor_body
        self.wall_body_ids = bodies.wall_body_ids
        self.obstacle_body_ids = bodies.obstacle_body_ids
        self.object_body_ids = bodies.object_body_ids
        #: body id → (kind, index, role): kind "object" | "obstacle" | "wall" | "floor" | "glass"
        self.body_info = bodies.body_info
        self.robot_body = bodies.robot_body
        self._robot_inertial_offset = bodies.robot_inertial_offset
        self._wheel_joint_index = bodies.wheel_joint_index
        self._world_bodies = bodies.world_bodies
        self._probe = CollisionProbe(p, self.client, bodies.probe, z=bodies.probe_z, radius=bodies.robot_radius,
                                     sim_config=config.sim, world_bodies=bodies.world_bodies)
        self._lidar = Lidar(p, self.client, bodies.world_bodies)
        # the EGL plugin's shadow-map pass (app/sim/egl_shadow.py): two thirds of a frame on llvmpipe
        shadow_map = bool(getattr(config.sim, "egl_shadow_map", False))
        shadow_switch = None
        if self.renderer == "egl":
            shadow_switch, why = shadow_map_switch(egl_plugin_path())
            if shadow_switch is None and not shadow_map:
                log.warning("the EGL plugin's shadow map cannot be switched off: %s", why)
                self.renderer_note += f", shadow map (cannot be switched off: {why})"
            else:
                self.renderer_note += ", shadow map" if shadow_map else ", no shadow map"
        self._camera = Camera(p, self.client, renderer=self.renderer, seg_lut=bodies.seg_lut, gl_thread=self._gl_thread,
                              shadow_switch=shadow_switch, shadow_map=shadow_map)
        self._robot_synced = False
        self.reset()

    # ------------------------------------------------------------------------------------------
    # state
    # ------------------------------------------------------------------------------------------
    def reset(self) -> None:
        """Back to the world's start pose at t = 0, wheels at zero, noise re-seeded.

        Each noise source has its own stream (motion/slip, encoders, LIDAR, camera) spawned from the
        seed, so which sensors are read, and how often, never changes the robot's true trajectory."""
        ss = np.random.SeedSequence(self.seed)
        self.rng_motion, self.rng_encoders, self.rng_lidar, self.rng_camera = (np.random.default_rng(s) for s in ss.spawn(4))
        self.time = 0.0
        self._steps = 0
        self._drive = KinematicDrive(self.world.start, self.rng_motion, self.config.encoders)
        self._robot_synced = False
        self._pixel_noise = PixelNoise(self.rng_camera)

    @property
    def robot_radius(self) -> float:
        """The robot's collision cylinder radius (``robot.footprint_radius_m`` when the world was built)."""
        return self._probe.radius

    @property
    def collisions(self) -> int:
        """How many times the robot ran into something since :meth:`reset` (a stall counts once)."""
        return self._drive.collisions

    @property
    def distance_m(self) -> float:
        """True distance driven since :meth:`reset` (m)."""
        return self._drive.distance_m

    @property
    def wheel_angles(self) -> tuple[float, float]:
        """True (left, right) wheel angles in rad (ground truth; the encoders add noise)."""
        phi = self._drive.phi
        return float(phi[0]), float(phi[1])

    def true_pose(self) -> Pose2:
        """Ground truth ``T_world_base`` (``base_footprint`` in the world frame)."""
        pose = self._drive.pose
        return Pose2(float(pose[0]), float(pose[1]), float(wrap_angle(pose[2])))

    def set_time(self, t: float) -> None:
        """Set the sim clock (restoring a session), rounded to whole physics steps."""
        self._steps = max(0, int(round(float(t) / self.dt)))
        self.time = self._steps * self.dt

    def set_robot_pose(self, T_world_base: Pose2) -> None:
        """Teleport the robot (no collision check; motion state kept, stall cleared)."""
        self._drive.pose = np.array([T_world_base.x, T_world_base.y, T_world_base.yaw], dtype=np.float64)
        self._drive.blocked = False
        self._robot_synced = False

    def set_cmd_vel(self, twist: Twist) -> None:
        """cmd_vel: wheel-rate targets from :func:`twist_to_wheel_rates` (clamped to the robot's limits)."""
        wl, wr = twist_to_wheel_rates(twist, self.config.robot)
        self._drive.omega_cmd = np.array([wl, wr], dtype=np.float64)

    def in_collision(self) -> bool:
        """True while the robot is stalled against an obstacle (its last step was refused)."""
        return self._drive.blocked

    def pose_free(self, x: float, y: float) -> bool:
        """True if the robot's collision cylinder at ``(x, y)`` touches nothing."""
        return self._probe.free(x, y)

    def step(self, n: int = 1) -> None:
        """Advance ``n`` fixed steps of ``dt``."""
        n = int(n)
        if n <= 0:
            return
        rm = self.robot_model
        if self._drive.step(n, self.dt, wheel_radius_m=rm.wheel_radius_m, wheel_separation_m=rm.wheel_separation_m,
                            motor_time_constant_s=self.config.sim.motor_time_constant_s, encoders=self.config.encoders,
                            pose_free=self.pose_free):
            self._robot_synced = False
        self._steps += n
        self.time = self._steps * self.dt

    # ------------------------------------------------------------------------------------------
    # sensors
    # ------------------------------------------------------------------------------------------
    def read_encoders(self) -> WheelEncoders:
        """Absolute wheel angles with Gaussian reading noise and quantisation, stamped with sim time."""
        e = self.config.encoders
        phi = self._drive.phi.copy()
        if e.noise_std_rad > 0:
            phi = phi + self.rng_encoders.normal(0.0, e.noise_std_rad, 2)
        if e.resolution_rad > 0:
            phi = np.round(phi / e.resolution_rad) * e.resolution_rad
        return WheelEncoders(stamp=self.time, left_rad=float(phi[0]), right_rad=float(phi[1]))

    def T_world_base3(self) -> NDArray[np.float64]:
        """``(4, 4)`` ground-truth pose of base_footprint (on the floor)."""
        return pose3(self.true_pose())

    def scan(self) -> LaserScan:
        """One LIDAR sweep from ``base_scan``: ``beams`` rays over 360° from -π, Gaussian range noise,
        ``inf`` for no return within ``range_max``, ``-inf`` for a return closer than ``range_min``."""
        T = self.T_world_base3() @ self.robot_model.T_base_scan
        return self._lidar.scan(T, self.config.lidar, self.rng_lidar, self.time)

    def camera_size(self) -> tuple[int, int]:
        """The default render size: ``camera.render_width`` (aspect kept) or the full ``width × height``."""
        return camera_size(self.config.camera)

    def camera_info(self, width: int | None = None, height: int | None = None) -> CameraInfo:
        """Ideal pinhole intrinsics at a render size (K from the horizontal FOV)."""
        if width is None or height is None:
            width, height = self.camera_size()
        return CameraInfo.from_fov(int(width), int(height), self.config.camera.hfov_rad)

    def _sync_robot(self) -> None:
        if self._robot_synced:
            return
        p, cid = self._p, self.client
        M = self.T_world_base3()
        pos = M[:3, :3] @ self._robot_inertial_offset + M[:3, 3]
        q = p.getQuaternionFromEuler([0.0, 0.0, float(self._drive.pose[2])])
        p.resetBasePositionAndOrientation(self.robot_body, pos.tolist(), q, physicsClientId=cid)
        for name, phi in zip(self.robot_model.wheel_joint_names, self._drive.phi):
            j = self._wheel_joint_index.get(name)
            if j is not None:
                p.resetJointState(self.robot_body, j, float(phi), physicsClientId=cid)
        self._robot_synced = True

    def render_camera(
        self, width: int | None = None, height: int | None = None, *, depth: bool = False, segmentation: bool = False
    ) -> CameraFrame:
        """The robot's camera (``camera_optical_frame``), with pixel noise ``camera.noise_std``."""
        if width is None or height is None:
            width, height = self.camera_size()
        self._sync_robot()
        T = self.T_world_base3() @ self.robot_model.T_base_camera_optical
        frame = self._render(T, int(width), int(height), depth=depth, segmentation=segmentation)
        sigma = float(self.config.camera.noise_std)
        if sigma > 0:
            frame.image = Image(stamp=frame.stamp, data=self._pixel_noise.add(frame.image.data, sigma))
        return frame

    def view_camera_pose(
        self, T_world_base: Pose2, *, camera_z: float | None = None, pitch_rad: float = 0.0
    ) -> NDArray[np.float64]:
        """``T_world_camera`` ``(4, 4)`` (optical frame) of :meth:`render_view`'s camera for a robot at
        ``T_world_base`` (``camera_z``, ``pitch_rad``: as there)."""
        T = pose3(T_world_base) @ self.robot_model.T_base_camera_optical
        if camera_z is not None:
            T[2, 3] = float(camera_z)
        if pitch_rad:
            c, s = math.cos(-pitch_rad), math.sin(-pitch_rad)
            Rx = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
            T[:3, :3] = T[:3, :3] @ Rx
        return T

    def render_view(
        self,
        T_world_base: Pose2,
        *,
        width: int,
        height: int,
        camera_z: float | None = None,
        pitch_rad: float = 0.0,
        light: dict | None = None,
        segmentation: bool = True,
        depth: bool = False,
        hide_robot: bool = True,
    ) -> CameraFrame:
        """Render from the camera of a robot standing at ``T_world_base`` (for datasets).

        ``camera_z`` replaces the optical centre's height; ``pitch_rad > 0`` tilts the camera down.
        ``light``: pybullet ``getCameraImage`` light arguments (``lightDirection``, ``lightColor``,
        ``lightAmbientCoeff``, ``lightDiffuseCoeff``, ``lightSpecularCoeff``, ``shadow``). The simulated
        robot is moved out of view unless ``hide_robot`` is False. No pixel noise is added.
        """
        T = self.view_camera_pose(T_world_base, camera_z=camera_z, pitch_rad=pitch_rad)
        p, cid = self._p, self.client
        if hide_robot:
            p.resetBasePositionAndOrientation(self.robot_body, list(FAR_AWAY), [0, 0, 0, 1], physicsClientId=cid)
            self._robot_synced = False
        else:
            self._sync_robot()
        return self._render(T, int(width), int(height), depth=depth, segmentation=segmentation, light=light)

    def _render(
        self,
        T_world_cam: NDArray[np.float64],
        width: int,
        height: int,
        *,
        depth: bool,
        segmentation: bool,
        light: dict | None = None,
    ) -> CameraFrame:
        return self._camera.render(T_world_cam, width, height, camera=self.config.camera, sim=self.config.sim,
                                   stamp=self.time, depth=depth, segmentation=segmentation, light=light)

    # ------------------------------------------------------------------------------------------
    # ground truth
    # ------------------------------------------------------------------------------------------
    def ground_truth_objects(self) -> list[GroundTruthObject]:
        """Every classified object: id (= index in ``world.objects``, as in segmentations), class,
        pose, CCW footprint polygon and height range, in the world frame."""
        return ground_truth_objects(self.world)

    def ground_truth_obstacles(self) -> list[GroundTruthObstacle]:
        """Walls (one entry per solid piece, openings cut out) and unclassified obstacles, world frame."""
        return ground_truth_obstacles(self.world)

    # ------------------------------------------------------------------------------------------
    # domain randomisation helpers
    # ------------------------------------------------------------------------------------------
    def set_body_color(self, body: int, rgb: Sequence[float]) -> None:
        self._p.changeVisualShape(body, -1, rgbaColor=[*map(float, rgb[:3]), 1.0], physicsClientId=self.client)

    def set_object_color(self, object_id: int, rgb: Sequence[float], role: str | None = None) -> None:
        """Recolour an object's parts of ``role`` (default: the model's primary role)."""
        spec = get_model(self.world.objects[object_id].model)
        role = role or spec.primary
        for b in self.object_body_ids[object_id]:
            if self.body_info[b][2] == role:
                self.set_body_color(b, rgb)

    def set_floor_color(self, rgb: Sequence[float]) -> None:
        self.set_body_color(self.floor_body, rgb)

    def set_wall_color(self, rgb: Sequence[float]) -> None:
        for ids in self.wall_body_ids:
            for b in ids:
                if self.body_info[b][0] == "wall":
                    self.set_body_color(b, rgb)

    def close(self) -> None:
        """Disconnect the pybullet client, or give a lent one back (idempotent)."""
        if getattr(self, "client", -1) >= 0:
            if getattr(self, "_camera", None) is not None:
                self._camera.shadow_switch = None  # the plugin may be unloaded with this client: its flag with it
            if self._owns_client:
                self._render_client.close()
            self.client = -1

    def __enter__(self) -> SimWorld:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:  # pragma: no cover - best effort
        try:
            self.close()
        except Exception:
            pass
