"""The topics OCSLAM records, as a TurtleBot3 running our nodes would publish them (REP-105 frames).

=================================  ======================================  =================================
topic                              type                                    frame / notes
=================================  ======================================  =================================
``/tf``                            tf2_msgs/msg/TFMessage                  ``map → odom`` (per scan),
                                                                           ``odom → base_footprint`` (per odom)
``/tf_static``                     tf2_msgs/msg/TFMessage                  ``base_footprint → base_link →
                                                                           {base_scan, camera_link →
                                                                           camera_optical_frame}``, once
``/odom``                          nav_msgs/msg/Odometry                   ``odom`` → ``base_footprint``
``/scan``                          sensor_msgs/msg/LaserScan               ``base_scan``
``/cmd_vel``                       geometry_msgs/msg/Twist                 (no header; 10 Hz while driving)
``/camera/image_raw/compressed``   sensor_msgs/msg/CompressedImage         ``camera_optical_frame``, JPEG
``/camera/camera_info``            sensor_msgs/msg/CameraInfo              ``camera_optical_frame``
``/yolo_boxes``                    std_msgs/msg/Float32MultiArray          layout below
``/objects``                       vision_msgs/msg/Detection3DArray        ``map`` (1 Hz and at the end)
``/objects/markers``               visualization_msgs/msg/MarkerArray      ``map``: cubes + labels
``/map``                           nav_msgs/msg/OccupancyGrid              ``map``, 1 Hz and at the end
``/slam/pose_graph``               visualization_msgs/msg/MarkerArray      ``map``: keyframes, odometry
                                                                           edges, loop closures
``/ground_truth/pose``             geometry_msgs/msg/PoseStamped           ``map``, the true base pose at
                                                                           each scan stamp
``/ground_truth/objects``          vision_msgs/msg/Detection3DArray        ``map``: true objects (once)
``/ground_truth/footprints``       visualization_msgs/msg/MarkerArray      ``map``: true footprints (once)
``/ocslam/scan_ranges``            std_msgs/msg/Float64MultiArray          exact ranges of each ``/scan``
``/ocslam/yolo_boxes``             std_msgs/msg/Float64MultiArray          exact boxes of each ``/yolo_boxes``
=================================  ======================================  =================================

Stamps are sim time (the run starts at 0 s); a message's bag (log) time is when the loop produced it,
so a camera frame is logged ``camera.latency_s`` after its header stamp, as a real driver's is.

``/yolo_boxes`` is the paper's box matrix as ``Float32MultiArray``: ``N`` rows of
``x1, y1, x2, y2, class_id, confidence_pct`` (pixels of the original image, top-left origin; ``class_id``
indexes :data:`app.ocslam.messages.CLASS_NAMES`; ``confidence_pct`` = confidence × 100, not floored,
so the paper's integer row is its ``floor``). ``layout.dim[0]`` is ``{label: "boxes stamp=S.NNNNNNNNN
image=WxH", size: N, stride: 6N}`` (the stamp and size of the image the boxes are in, since the message
has no header) and ``layout.dim[1]`` is ``{label: "x1,y1,x2,y2,class_id,confidence_pct", size: 6, stride: 6}``.

Two OCSLAM topics make a replay bit-identical to the live run: ``/ocslam/scan_ranges`` and
``/ocslam/yolo_boxes`` (std_msgs/Float64MultiArray) carry the float64 ranges and boxes the core used
(LaserScan and ``/yolo_boxes`` are float32), logged with the message they complete; the bag's
``custom_data`` ``ocslam.stamp_step_s`` is the simulator's step, so stamps are restored to the exact
``steps × step`` floats of the live run. Other tools ignore them.

``/ground_truth/footprints`` markers are ``LINE_STRIP`` polygons (closed) at ``z = z_min`` with
``scale.z = z_max − z_min``; ``ns`` is ``objects``, ``objects_legged``, ``walls`` or ``obstacles``;
object markers carry the object's id (as in ``/ground_truth/objects``) and ``text`` = label.
"""

from __future__ import annotations

TF = "/tf"
TF_STATIC = "/tf_static"
ODOM = "/odom"
SCAN = "/scan"
CMD_VEL = "/cmd_vel"
IMAGE_COMPRESSED = "/camera/image_raw/compressed"
IMAGE_RAW = "/camera/image_raw"
CAMERA_INFO = "/camera/camera_info"
YOLO_BOXES = "/yolo_boxes"
OBJECTS = "/objects"
OBJECT_MARKERS = "/objects/markers"
MAP = "/map"
POSE_GRAPH = "/slam/pose_graph"
GT_POSE = "/ground_truth/pose"
GT_OBJECTS = "/ground_truth/objects"
GT_FOOTPRINTS = "/ground_truth/footprints"
EXACT_RANGES = "/ocslam/scan_ranges"
EXACT_BOXES = "/ocslam/yolo_boxes"

#: topic → ROS 2 message type of everything :class:`app.ros2.recorder.BagRecorder` writes
RECORDED_TOPICS: dict[str, str] = {
    TF: "tf2_msgs/msg/TFMessage",
    TF_STATIC: "tf2_msgs/msg/TFMessage",
    ODOM: "nav_msgs/msg/Odometry",
    SCAN: "sensor_msgs/msg/LaserScan",
    CMD_VEL: "geometry_msgs/msg/Twist",
    IMAGE_COMPRESSED: "sensor_msgs/msg/CompressedImage",
    CAMERA_INFO: "sensor_msgs/msg/CameraInfo",
    YOLO_BOXES: "std_msgs/msg/Float32MultiArray",
    OBJECTS: "vision_msgs/msg/Detection3DArray",
    OBJECT_MARKERS: "visualization_msgs/msg/MarkerArray",
    MAP: "nav_msgs/msg/OccupancyGrid",
    POSE_GRAPH: "visualization_msgs/msg/MarkerArray",
    GT_POSE: "geometry_msgs/msg/PoseStamped",
    GT_OBJECTS: "vision_msgs/msg/Detection3DArray",
    GT_FOOTPRINTS: "visualization_msgs/msg/MarkerArray",
    EXACT_RANGES: "std_msgs/msg/Float64MultiArray",
    EXACT_BOXES: "std_msgs/msg/Float64MultiArray",
}

#: the bag's custom_data key holding the simulator's step (s): every sim stamp is a whole number of steps
STAMP_STEP_KEY = "ocslam.stamp_step_s"

#: topics written once, that late subscribers must still get (transient-local QoS)
LATCHED_TOPICS: frozenset[str] = frozenset({TF_STATIC, GT_OBJECTS, GT_FOOTPRINTS})

#: the static frame tree written to ``/tf_static``: (parent, child)
STATIC_FRAMES: tuple[tuple[str, str], ...] = (
    ("base_footprint", "base_link"),
    ("base_link", "base_scan"),
    ("base_link", "camera_link"),
    ("camera_link", "camera_optical_frame"),
)

YOLO_COLUMNS = "x1,y1,x2,y2,class_id,confidence_pct"
