"""The ROS 2 type store used to write and read bags: ROS 2 Jazzy's types plus vision_msgs.

vision_msgs is not part of ROS 2's core message set, so its definitions (vision_msgs 4.x, as shipped
with Humble and Jazzy) are registered here from their ``.msg`` text; the bag then carries them, so
Foxglove and ``ros2 bag`` decode ``/objects`` without the package installed.
"""

from __future__ import annotations

from functools import lru_cache

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

#: vision_msgs 4.x message definitions (``ros-perception/vision_msgs``, ``msg/*.msg``, comments removed)
VISION_MSGS: dict[str, str] = {
    "vision_msgs/msg/ObjectHypothesis": "string class_id\nfloat64 score\n",
    "vision_msgs/msg/ObjectHypothesisWithPose": (
        "vision_msgs/ObjectHypothesis hypothesis\ngeometry_msgs/PoseWithCovariance pose\n"
    ),
    "vision_msgs/msg/BoundingBox3D": "geometry_msgs/Pose center\ngeometry_msgs/Vector3 size\n",
    "vision_msgs/msg/Detection3D": (
        "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\n"
        "vision_msgs/BoundingBox3D bbox\nstring id\n"
    ),
    "vision_msgs/msg/Detection3DArray": "std_msgs/Header header\nvision_msgs/Detection3D[] detections\n",
}


@lru_cache(maxsize=1)
def ros2_typestore() -> Typestore:
    """ROS 2 Jazzy's standard types + vision_msgs (built once; treat as read-only)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    types: dict = {}
    for name, text in VISION_MSGS.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


@lru_cache(maxsize=1)
def ros1_typestore() -> Typestore:
    """ROS 1 Noetic's types (+ tf2_msgs/TFMessage, which rosbags' Noetic store lacks): the fallback for
    ROS 1 bags without embedded definitions."""
    store = get_typestore(Stores.ROS1_NOETIC)
    if "tf2_msgs/msg/TFMessage" not in store.types:
        store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms\n", "tf2_msgs/msg/TFMessage"))
    return store
