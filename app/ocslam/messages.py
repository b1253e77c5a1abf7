"""Small dataclasses shaped like the ROS messages they stand for, stamped with sim time.

The core (``app.ocslam``) only consumes and produces these, so the same code runs on simulated
data, on CARMEN logs and on recorded robot data.

Frames follow REP-103/105: ``map → odom → base_footprint → base_link → {base_scan,
camera_link → camera_optical_frame}``. x forward, y left, z up; optical frames are z forward,
x right, y down.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from app.ocslam.se2 import Pose2

#: The detector's classes, in the fixed order of the paper's ``data/model.yaml``.
CLASS_NAMES: tuple[str, ...] = (
    "ball",
    "dog",
    "gnome",
    "table",
    "chair",
    "door",
    "duck",
    "person",
    "extinguisher",
    "flowers",
    "shelf",
)
CLASS_INDEX: dict[str, int] = {name: i for i, name in enumerate(CLASS_NAMES)}


@dataclass(frozen=True, slots=True)
class Twist:
    """geometry_msgs/Twist for a planar base: ``linear_x`` (m/s) forward, ``angular_z`` (rad/s) left."""

    linear_x: float = 0.0
    angular_z: float = 0.0


@dataclass(frozen=True, slots=True)
class WheelEncoders:
    """Absolute wheel angles (rad), like sensor_msgs/JointState of the two wheel joints."""

    stamp: float
    left_rad: float
    right_rad: float


@dataclass(frozen=True, slots=True)
class Odometry:
    """nav_msgs/Odometry: ``T_odom_base`` (pose of ``base_footprint`` in ``odom``) and body twist."""

    stamp: float
    T_odom_base: Pose2
    linear_x: float = 0.0
    angular_z: float = 0.0
    frame_id: str = "odom"
    child_frame_id: str = "base_footprint"


@dataclass(frozen=True, slots=True)
class LaserScan:
    """sensor_msgs/LaserScan.

    ``ranges`` is ``(N,)`` in metres; beam ``i`` points at ``angle_min + i * angle_increment`` in
    ``frame_id``. ``inf`` means no return within ``range_max``.
    """

    stamp: float
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    ranges: NDArray[np.float64]
    frame_id: str = "base_scan"

    @property
    def angles(self) -> NDArray[np.float64]:
        """``(N,)`` beam angles in ``frame_id``."""
        return self.angle_min + self.angle_increment * np.arange(len(self.ranges), dtype=np.float64)

    def valid_mask(self) -> NDArray[np.bool_]:
        """``(N,)`` True for finite ranges inside ``[range_min, range_max]``."""
        r = np.asarray(self.ranges, dtype=np.float64)
        with np.errstate(invalid="ignore"):
            return np.isfinite(r) & (r >= self.range_min) & (r <= self.range_max)

    def points(self) -> NDArray[np.float64]:
        """``(M, 2)`` points of the valid returns in ``frame_id``."""
        m = self.valid_mask()
        r = np.asarray(self.ranges, dtype=np.float64)[m]
        a = self.angles[m]
        return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)


@dataclass(frozen=True, slots=True)
class CameraInfo:
    """sensor_msgs/CameraInfo (pinhole, no distortion). ``K`` is ``(3, 3)``."""

    width: int
    height: int
    K: NDArray[np.float64]
    frame_id: str = "camera_optical_frame"

    @staticmethod
    def from_fov(width: int, height: int, hfov_rad: float, frame_id: str = "camera_optical_frame") -> CameraInfo:
        """Ideal pinhole K from the horizontal field of view; square pixels, centred principal point."""
        fx = (width / 2.0) / np.tan(hfov_rad / 2.0)
        K = np.array([[fx, 0.0, width / 2.0], [0.0, fx, height / 2.0], [0.0, 0.0, 1.0]])
        return CameraInfo(width=width, height=height, K=K, frame_id=frame_id)

    @property
    def fx(self) -> float:
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        return float(self.K[1, 2])

    def scaled(self, width: int, height: int) -> CameraInfo:
        """The same camera at another resolution."""
        sx, sy = width / self.width, height / self.height
        K = self.K.copy()
        K[0] *= sx
        K[1] *= sy
        return CameraInfo(width=width, height=height, K=K, frame_id=self.frame_id)


@dataclass(frozen=True, slots=True)
class Image:
    """sensor_msgs/Image, RGB8: ``data`` is ``(H, W, 3)`` uint8."""

    stamp: float
    data: NDArray[np.uint8]
    frame_id: str = "camera_optical_frame"

    @property
    def width(self) -> int:
        return int(self.data.shape[1])

    @property
    def height(self) -> int:
        return int(self.data.shape[0])


@dataclass(frozen=True, slots=True)
class Detection:
    """One detector box in original-image pixels (origin top-left, y down)."""

    x1: float
    y1: float
    x2: float
    y2: float
    class_id: int
    confidence: float

    @property
    def label(self) -> str:
        return CLASS_NAMES[self.class_id]

    @property
    def width(self) -> float:
        return self.x2 - self.x1

    @property
    def height(self) -> float:
        return self.y2 - self.y1


@dataclass(frozen=True, slots=True)
class Detections:
    """All boxes of one image (the paper's ``/yolo_boxes`` message)."""

    stamp: float
    image_width: int
    image_height: int
    boxes: tuple[Detection, ...] = ()

    def yolo_boxes(self) -> NDArray[np.int32]:
        """The paper's ``/yolo_boxes`` matrix: ``(N, 6)`` int rows ``x1, y1, x2, y2, class, floor(conf*100)``."""
        if not self.boxes:
            return np.zeros((0, 6), dtype=np.int32)
        return np.array(
            [[b.x1, b.y1, b.x2, b.y2, b.class_id, np.floor(b.confidence * 100.0)] for b in self.boxes]
        ).astype(np.int32)

    def __len__(self) -> int:
        return len(self.boxes)


@dataclass(slots=True)
class OccupancyGrid:
    """nav_msgs/OccupancyGrid: ``data`` is ``(H, W)`` int8, -1 unknown, 0..100 occupancy.

    Cell ``(row i, col j)`` covers ``origin ∘ ((j + 0.5)·res, (i + 0.5)·res)`` in ``frame_id``:
    columns run along the origin's +x, rows along its +y (the ROS layout, row 0 at the bottom).
    """

    resolution: float
    origin: Pose2
    data: NDArray[np.int8]
    stamp: float = 0.0
    frame_id: str = "map"

    @property
    def width(self) -> int:
        return int(self.data.shape[1])

    @property
    def height(self) -> int:
        return int(self.data.shape[0])

    def cell_centers(self) -> NDArray[np.float64]:
        """``(H, W, 2)`` cell centres in ``frame_id``."""
        j, i = np.meshgrid(np.arange(self.width), np.arange(self.height))
        local = np.stack([(j + 0.5) * self.resolution, (i + 0.5) * self.resolution], axis=-1)
        return self.origin.transform_points(local.reshape(-1, 2)).reshape(self.height, self.width, 2)

    def world_to_cell(self, points: NDArray[np.float64]) -> NDArray[np.int64]:
        """``(N, 2)`` points in ``frame_id`` → ``(N, 2)`` integer ``(row, col)`` (may be out of bounds)."""
        o = self.origin
        if o.yaw == 0.0:
            # an unrotated origin (SLAM's grids): the inverse transform is a shift (x·1 + y·(−0) − x₀ is x − x₀ in
            # IEEE arithmetic: the same cells, without the transform's overhead)
            local = np.asarray(points, dtype=np.float64).reshape(-1, 2) - np.array([o.x, o.y], dtype=np.float64)
        else:
            local = o.inverse().transform_points(points)
        out = np.empty((len(local), 2), dtype=np.int64)
        out[:, 0] = np.floor(local[:, 1] / self.resolution)
        out[:, 1] = np.floor(local[:, 0] / self.resolution)
        return out


@dataclass(slots=True)
class TrackedObject:
    """One object of the object map, shaped after vision_msgs/Detection3D.

    ``pose`` is the centre in ``frame_id`` (``map`` in improved mode, ``odom`` in seed mode);
    ``size_x``/``size_y`` are the footprint's extents along the object's own axes (``pose.yaw``),
    ``size_z`` its height when known.
    """

    id: int
    label: str
    pose: Pose2
    size_x: float
    size_y: float
    size_z: float = 0.0
    presence: float = 0.0
    detection_confidence: float = 0.0
    frames_seen: int = 1
    source: str = "lidar_island"  # "lidar_island" | "lidar_legs" | "ground_plane"
    frame_id: str = "map"
    anchor_keyframe: int | None = None
    T_keyframe_object: Pose2 | None = None
    last_seen: float = 0.0
    footprint: NDArray[np.float64] | None = field(default=None, repr=False)  # (K, 2) polygon in frame_id

    @property
    def class_id(self) -> int:
        return CLASS_INDEX[self.label]


@dataclass(frozen=True, slots=True)
class GroundTruthObject:
    """A classified object as the simulator knows it (ground truth: only for evaluation and overlays).

    ``pose`` and ``footprint`` (``(K, 2)`` polygon, counter-clockwise) are in ``frame_id``
    (the simulator's ``world`` frame; ``app.pipeline`` re-expresses them in ``map``).
    ``z_min``/``z_max`` bound the object's height above the floor; ``legged`` marks objects whose
    LIDAR cross-section is several separate legs.
    """

    id: int
    label: str
    pose: Pose2
    footprint: NDArray[np.float64]
    z_min: float
    z_max: float
    legged: bool = False
    name: str = ""
    frame_id: str = "world"

    @property
    def height(self) -> float:
        return self.z_max - self.z_min


@dataclass(frozen=True, slots=True)
class GroundTruthObstacle:
    """An unclassified obstacle or wall piece (ground truth): ``(K, 2)`` polygon, height range."""

    footprint: NDArray[np.float64]
    z_min: float
    z_max: float
    kind: str = "obstacle"  # "wall" | "obstacle"
    name: str = ""
    frame_id: str = "world"
