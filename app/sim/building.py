"""A world loaded into a pybullet client: floor, walls, glass, obstacles, objects, the robot and its probe.

One static body per model part, walls as boxes with their openings cut out (a window's glass is a thin
box of its own), a floor under the whole world, and the robot loaded from its URDF (moved kinematically,
visual only). Collision filter groups keep the LIDAR's rays and the robot's collision probe on the world
bodies. Bodies are created in a fixed order (floor, walls, obstacles, objects, robot, probe), so a world
gets the same body ids every time (the segmentation lookup maps them to ground-truth object ids).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.sim.robot_model import RobotModel
from app.world.models.bodies import body_flags, build_model_pybullet
from app.world.models.catalogue import get_model
from app.world.models.colors import resolve_colors
from app.world.types import World

__all__ = ["FAR_AWAY", "G_CHECK", "G_FLOOR", "G_ROBOT", "G_WORLD", "Bodies", "build_bodies"]

# collision filter groups: rays and the robot's collision query only see WORLD bodies
G_WORLD, G_ROBOT, G_FLOOR, G_CHECK = 1, 2, 4, 8
GLASS = (0.62, 0.78, 0.9)
#: where a body out of view waits (the collision probe between queries, the robot hidden from a render)
FAR_AWAY = (0.0, 0.0, -50.0)


@dataclass
class Bodies:
    """The pybullet bodies of a world and what each one is."""

    floor_body: int
    wall_body_ids: list[list[int]]  # per wall: its solid pieces, then its windows' glass
    obstacle_body_ids: list[list[int]]  # per obstacle
    object_body_ids: dict[int, list[int]]  # object index (= ground-truth id) → its parts
    #: body id → (kind, index, role): kind "object" | "obstacle" | "wall" | "floor" | "glass"
    body_info: dict[int, tuple[str, int, str]]
    world_bodies: set[int]  # what the LIDAR and the collision probe see (all but the floor and the robot)
    seg_lut: NDArray[np.int32]  # body id → ground-truth object id, -1 otherwise
    robot_body: int
    robot_inertial_offset: NDArray[np.float64]  # (3,) the URDF base's centre of mass in its link frame
    wheel_joint_index: dict[str, int]  # joint name → pybullet joint index
    robot_radius: float  # the collision cylinder's radius (robot.footprint_radius_m)
    probe: int  # the collision cylinder's body
    probe_z: float  # the collision cylinder's centre height


def build_bodies(
    p: Any,
    cid: int,
    world: World,
    robot_model: RobotModel,
    config: Any,
    *,
    mesh_file: Callable[[str, Sequence[float]], str] | None = None,
) -> Bodies:
    """Create every body of ``world`` and the robot in pybullet client ``cid`` (``config``: the root
    ``Config``: ``robot.footprint_radius_m`` and ``sim.robot_height_m`` size the collision probe).
    ``mesh_file``: maps a mesh file and its scale to the file name to load (the EGL renderer's
    :func:`~app.sim.renderer.egl_mesh_alias`)."""
    body_info: dict[int, tuple[str, int, str]] = {}
    object_body_ids: dict[int, list[int]] = {}
    wall_body_ids: list[list[int]] = []
    obstacle_body_ids: list[list[int]] = []
    world_bodies: set[int] = set()
    w, mf = world, mesh_file
    xmin, ymin, xmax, ymax = w.bounds()
    cx, cy = (xmin + xmax) / 2, (ymin + ymax) / 2
    hx, hy = (xmax - xmin) / 2 + 1.0, (ymax - ymin) / 2 + 1.0
    floor = p.createMultiBody(
        0.0,
        p.createCollisionShape(p.GEOM_BOX, halfExtents=[hx, hy, 0.005], physicsClientId=cid),
        p.createVisualShape(p.GEOM_BOX, halfExtents=[hx, hy, 0.005], rgbaColor=[*w.floor_color, 1.0], physicsClientId=cid),
        [cx, cy, -0.005],
        flags=body_flags(p),
        physicsClientId=cid,
    )
    body_info[floor] = ("floor", 0, "floor")
    p.setCollisionFilterGroupMask(floor, -1, G_FLOOR, 0, physicsClientId=cid)
    for i, wall in enumerate(w.walls):
        ids = []
        color = wall.color or w.wall_color
        for s0, s1, z0, z1, th, yaw in wall.boxes():
            mx, my = wall.point_at((s0 + s1) / 2)
            he = [(s1 - s0) / 2, th / 2, (z1 - z0) / 2]
            b = _static_box(p, cid, he, (mx, my, (z0 + z1) / 2), yaw, color)
            body_info[b] = ("wall", i, "wall")
            ids.append(b)
        for o in wall.openings:
            if o.kind != "window":
                continue
            mx, my = wall.point_at((o.start + o.end) / 2)
            he = [(o.end - o.start) / 2, 0.01, (o.top - o.bottom) / 2]
            b = _static_box(p, cid, he, (mx, my, (o.bottom + o.top) / 2), wall.yaw, GLASS)
            body_info[b] = ("glass", i, "glass")
            ids.append(b)
        wall_body_ids.append(ids)
    for i, o in enumerate(w.obstacles):
        ids = []
        if o.shape == "box":
            ids.append(_static_box(p, cid, [v / 2 for v in o.size], (o.x, o.y, o.z + o.size[2] / 2), o.yaw, o.color or (0.6, 0.6, 0.6)))
        elif o.shape == "cylinder":
            col = p.createCollisionShape(p.GEOM_CYLINDER, radius=o.radius, height=o.height, physicsClientId=cid)
            vis = p.createVisualShape(
                p.GEOM_CYLINDER, radius=o.radius, length=o.height, rgbaColor=[*(o.color or (0.6, 0.6, 0.6)), 1.0], physicsClientId=cid
            )
            ids.append(p.createMultiBody(0.0, col, vis, [o.x, o.y, o.z + o.height / 2], flags=body_flags(p), physicsClientId=cid))
        else:
            spec = get_model(o.model)
            built = build_model_pybullet(cid, o.model, o.x, o.y, o.yaw, z=o.z, scale=o.scale, colors=resolve_colors(spec, o.color), mesh_file=mf)
            ids.extend(b for b, _ in built)
            for b, role in built:
                body_info[b] = ("obstacle", i, role)
        for b in ids:
            body_info.setdefault(b, ("obstacle", i, "body"))
        obstacle_body_ids.append(ids)
    for i, o in enumerate(w.objects):
        spec = get_model(o.model)
        built = build_model_pybullet(cid, o.model, o.x, o.y, o.yaw, scale=o.scale, colors=resolve_colors(spec, o.color), mesh_file=mf)
        object_body_ids[i] = [b for b, _ in built]
        for b, role in built:
            body_info[b] = ("object", i, role)
    for b, (kind, _, _) in body_info.items():
        if kind != "floor":
            p.setCollisionFilterGroupMask(b, -1, G_WORLD, G_WORLD, physicsClientId=cid)
            world_bodies.add(b)
    # segmentation lookup: body id → ground-truth object id (-1 otherwise)
    n = max(body_info) + 64
    seg_lut = np.full(n + 1, -1, dtype=np.int32)
    for b, (kind, i, _) in body_info.items():
        if kind == "object":
            seg_lut[b] = i
    # the robot (kinematic, visual only) and its collision probe
    rm = robot_model
    robot_body = p.loadURDF(
        str(rm.urdf_path),
        [0, 0, 0],
        useFixedBase=True,
        flags=p.URDF_USE_IMPLICIT_CYLINDER,
        physicsClientId=cid,
    )
    robot_inertial_offset = np.asarray(p.getDynamicsInfo(robot_body, -1, physicsClientId=cid)[3])
    wheel_joint_index: dict[str, int] = {}
    for j in range(p.getNumJoints(robot_body, physicsClientId=cid)):
        info = p.getJointInfo(robot_body, j, physicsClientId=cid)
        wheel_joint_index[info[1].decode()] = j
        p.setCollisionFilterGroupMask(robot_body, j, G_ROBOT, 0, physicsClientId=cid)
    p.setCollisionFilterGroupMask(robot_body, -1, G_ROBOT, 0, physicsClientId=cid)
    robot_radius = float(config.robot.footprint_radius_m)
    h = float(config.sim.robot_height_m)
    probe_z = (0.012 + h) / 2  # from 12 mm above the floor (rugs, cables) to the robot's top
    probe_col = p.createCollisionShape(p.GEOM_CYLINDER, radius=robot_radius, height=h - 0.012, physicsClientId=cid)
    probe = p.createMultiBody(0.0, probe_col, -1, list(FAR_AWAY), flags=body_flags(p), physicsClientId=cid)
    p.setCollisionFilterGroupMask(probe, -1, G_CHECK, 0, physicsClientId=cid)
    return Bodies(
        floor_body=floor,
        wall_body_ids=wall_body_ids,
        obstacle_body_ids=obstacle_body_ids,
        object_body_ids=object_body_ids,
        body_info=body_info,
        world_bodies=world_bodies,
        seg_lut=seg_lut,
        robot_body=robot_body,
        robot_inertial_offset=robot_inertial_offset,
        wheel_joint_index=wheel_joint_index,
        robot_radius=robot_radius,
        probe=probe,
        probe_z=probe_z,
    )


def _static_box(p: Any, cid: int, he: Sequence[float], pos: Sequence[float], yaw: float, color: Sequence[float]) -> int:
    col = p.createCollisionShape(p.GEOM_BOX, halfExtents=list(he), physicsClientId=cid)
    vis = p.createVisualShape(p.GEOM_BOX, halfExtents=list(he), rgbaColor=[*color[:3], 1.0], physicsClientId=cid)
    q = p.getQuaternionFromEuler([0.0, 0.0, yaw])
    return p.createMultiBody(0.0, col, vis, list(pos), q, flags=body_flags(p), physicsClientId=cid)

