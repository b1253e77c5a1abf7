"""The TurtleBot3 Burger's geometry, read from its URDF: sensor extrinsics and wheel dimensions.

Everything downstream takes the extrinsics from here: the camera projection ``P = K [R | t]``, the
LIDAR frame, the viser TF axes. Frames follow REP-103 (x forward, y left, z up; the camera optical
frame has z forward, x right, y down). ``T_a_b`` is the pose of frame ``b`` in frame ``a`` (a (4, 4)
homogeneous matrix mapping points in ``b`` to ``a``). ``base`` means ``base_footprint``: on the floor
under the wheel-axle midpoint.

Example:
    >>> robot = RobotModel.load()
    >>> robot.lidar_height_m  # 0.173
    >>> p_optical = np.linalg.inv(robot.T_base_camera_optical) @ [1.0, 0.0, 0.19, 1.0]
    >>> p_optical[2]  # ≈ 0.97: a point 1 m ahead of the robot is in front of the camera

pybullet note (for the simulator): load with ``flags=URDF_USE_IMPLICIT_CYLINDER |
URDF_USE_INERTIA_FROM_FILE`` (otherwise the wheel cylinders become convex hulls and the robot rides
1 mm high with a 0.7° pitch), and read link poses from ``getLinkState(...)[4:6]`` (the URDF link
frame), not ``[0:2]`` (the centre of mass).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yourdfpy
from numpy.typing import NDArray

from app.config import ASSETS
from app.ocslam.se2 import Pose2

__all__ = ["DEFAULT_URDF", "RobotModel", "RobotModelError", "frame_transform", "link_poses"]

FloatArray = NDArray[np.float64]

#: The project's TurtleBot3 Burger (meshes in ``assets/meshes/turtlebot3/``).
DEFAULT_URDF: Path = ASSETS / "urdf" / "turtlebot3_burger.urdf"

BASE_FRAME = "base_footprint"
SCAN_FRAME = "base_scan"
CAMERA_LINK = "camera_link"
CAMERA_OPTICAL_FRAME = "camera_optical_frame"
WHEEL_JOINTS = ("wheel_left_joint", "wheel_right_joint")


class RobotModelError(ValueError):
    """The URDF is missing or does not describe a differential-drive robot with our frames."""


def link_poses(urdf: yourdfpy.URDF) -> dict[str, FloatArray]:
    """Pose ``T_root_link`` (4, 4) of every link in the URDF's root link, all joints at zero.

    Walks the joint origins from the root (movable joints at q = 0 contribute only their origin).
    Raises ``RobotModelError`` if a link is reachable from two joints (not a tree).
    """
    parent_joint: dict[str, yourdfpy.Joint] = {}
    for joint in urdf.robot.joints:
        if joint.child in parent_joint:
            raise RobotModelError(f"link {joint.child!r} is the child of two joints: not a tree")
        parent_joint[joint.child] = joint
    poses: dict[str, FloatArray] = {}

    def pose(link: str, depth: int = 0) -> FloatArray:
        if link in poses:
            return poses[link]
        if depth > len(urdf.robot.links):
            raise RobotModelError(f"kinematic loop through link {link!r}")
        joint = parent_joint.get(link)
        if joint is None:
            T = np.eye(4)
        else:
            origin = np.eye(4) if joint.origin is None else np.asarray(joint.origin, dtype=np.float64)
            T = pose(joint.parent, depth + 1) @ origin
        poses[link] = T
        return T

    for link in urdf.link_map:
        pose(link)
    return poses


def frame_transform(urdf: yourdfpy.URDF, parent: str, child: str) -> FloatArray:
    """``T_parent_child`` (4, 4): the pose of frame ``child`` in frame ``parent``, joints at zero.

    Any two links of the tree work (``child`` need not be a descendant of ``parent``).
    Raises ``RobotModelError`` naming an unknown link.
    """
    for name in (parent, child):
        if name not in urdf.link_map:
            raise RobotModelError(f"link {name!r} is not in the URDF (links: {sorted(urdf.link_map)})")
    poses = link_poses(urdf)
    return np.linalg.inv(poses[parent]) @ poses[child]


def _wheel_radius(urdf: yourdfpy.URDF, link_name: str) -> float:
    """Radius of the wheel link's cylinder (collision first, then visual)."""
    link = urdf.link_map[link_name]
    for geom in [c.geometry for c in link.collisions] + [v.geometry for v in link.visuals]:
        if geom is not None and geom.cylinder is not None:
            return float(geom.cylinder.radius)
        if geom is not None and geom.sphere is not None:
            return float(geom.sphere.radius)
    raise RobotModelError(
        f"wheel link {link_name!r} has no cylinder or sphere geometry to read its radius from"
    )


@dataclass(frozen=True, eq=False)
class RobotModel:
    """Geometry of a differential-drive robot read from its URDF (all poses in ``base_footprint``)."""

    urdf_path: Path
    wheel_radius_m: float
    wheel_separation_m: float
    T_base_scan: FloatArray  # (4, 4) pose of base_scan in base_footprint
    T_base_camera_optical: FloatArray  # (4, 4) pose of camera_optical_frame in base_footprint
    T_base_camera_link: FloatArray  # (4, 4) pose of camera_link in base_footprint
    wheel_joint_names: tuple[str, str] = WHEEL_JOINTS  # (left, right)
    #: (4, 4) pose of every link in base_footprint, joints at zero (for TF axes and checks)
    T_base_links: dict[str, FloatArray] = field(default_factory=dict, repr=False)

    @property
    def lidar_height_m(self) -> float:
        """Height of the LIDAR scan plane above the floor."""
        return float(self.T_base_scan[2, 3])

    @property
    def camera_height_m(self) -> float:
        """Height of the camera's optical centre above the floor."""
        return float(self.T_base_camera_optical[2, 3])

    def T_base_scan_2d(self) -> Pose2:
        """The LIDAR's planar pose ``(x, y, yaw)`` in base_footprint (for scan points → base)."""
        return _planar(self.T_base_scan)

    def T_base(self, link: str) -> FloatArray:
        """(4, 4) pose of ``link`` in base_footprint, joints at zero."""
        try:
            return self.T_base_links[link].copy()
        except KeyError:
            raise RobotModelError(f"link {link!r} is not in {self.urdf_path.name}") from None

    @classmethod
    def load(cls, path: Path | str | None = None) -> RobotModel:
        """Read the robot from a URDF (default: ``DEFAULT_URDF``). Meshes are not loaded.

        Wheel radius comes from the left/right wheel link's cylinder, the separation from the
        distance between the wheel joint origins. Raises ``RobotModelError`` with a clear message if
        the file is missing, malformed, or lacks the frames or wheel joints.
        """
        urdf_path = Path(path) if path is not None else DEFAULT_URDF
        if not urdf_path.is_file():
            raise RobotModelError(f"URDF not found: {urdf_path}")
        try:
            urdf = yourdfpy.URDF.load(str(urdf_path), load_meshes=False, build_scene_graph=False)
        except Exception as exc:  # yourdfpy raises lxml/ValueError/AttributeError on bad files
            raise RobotModelError(f"cannot parse URDF {urdf_path}: {exc}") from exc
        for name in (BASE_FRAME, SCAN_FRAME, CAMERA_LINK, CAMERA_OPTICAL_FRAME):
            if name not in urdf.link_map:
                raise RobotModelError(f"{urdf_path.name}: missing link {name!r}")
        wheel_links = []
        for jname in WHEEL_JOINTS:
            joint = urdf.joint_map.get(jname)
            if joint is None:
                raise RobotModelError(f"{urdf_path.name}: missing joint {jname!r}")
            if joint.type not in ("continuous", "revolute"):
                raise RobotModelError(f"{urdf_path.name}: {jname!r} is {joint.type!r}, expected continuous")
            wheel_links.append(joint.child)

        poses = link_poses(urdf)
        T_root_base_inv = np.linalg.inv(poses[BASE_FRAME])
        T_base_links = {name: T_root_base_inv @ T for name, T in poses.items()}
        for T in T_base_links.values():
            T.setflags(write=False)  # the model is shared by every consumer: read-only

        radii = [_wheel_radius(urdf, link) for link in wheel_links]
        if not np.isclose(radii[0], radii[1], rtol=1e-6):
            raise RobotModelError(f"{urdf_path.name}: wheel radii differ ({radii[0]} vs {radii[1]})")
        p_left = T_base_links[wheel_links[0]][:3, 3]
        p_right = T_base_links[wheel_links[1]][:3, 3]
        separation = float(np.linalg.norm(p_left - p_right))
        if p_left[1] <= p_right[1]:
            raise RobotModelError(f"{urdf_path.name}: the left wheel must be at +y (REP-103)")

        return cls(
            urdf_path=urdf_path,
            wheel_radius_m=radii[0],
            wheel_separation_m=separation,
            T_base_scan=T_base_links[SCAN_FRAME],
            T_base_camera_optical=T_base_links[CAMERA_OPTICAL_FRAME],
            T_base_camera_link=T_base_links[CAMERA_LINK],
            wheel_joint_names=WHEEL_JOINTS,
            T_base_links=T_base_links,
        )


def _planar(T: FloatArray) -> Pose2:
    """Project a (4, 4) pose onto the floor plane: ``(x, y, yaw)`` with yaw from the rotated x axis."""
    return Pose2(float(T[0, 3]), float(T[1, 3]), float(np.arctan2(T[1, 0], T[0, 0])))
