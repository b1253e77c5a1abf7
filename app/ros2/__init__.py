"""ROS 2 bags: record a run as a rosbag2 MCAP bag, and replay ROS 1 / rosbag2 bags through OCSLAM's core.

Pure Python on top of the ``rosbags`` package (no ROS installation needed). One concept per module:

- :mod:`app.ros2.typestore`: the ROS 2 type store, with vision_msgs registered from its ``.msg`` text.
- :mod:`app.ros2.topics`: the topic table (names, types, frames) and the ``/yolo_boxes`` layout.
- :mod:`app.ros2.convert`: our dataclasses (``app.ocslam.messages``) ↔ ROS 2 messages.
- :mod:`app.ros2.extrinsics`: 3D sensor extrinsics → the planar scan the core expects (an upside-down
  LIDAR mirrors its scan).
- :mod:`app.ros2.recorder`: :class:`BagRecorder` writes a live run's sensor events and results to MCAP.
- :mod:`app.ros2.reader`: :func:`read_bag` opens ROS 1 ``.bag``, rosbag2 sqlite3 and MCAP bags.
- :mod:`app.ros2.replay`: :class:`ReplayCore` feeds the core from a bag (scan, odometry, camera or the
  recorded ``/yolo_boxes``), with snapshots to seek.
- :mod:`app.ros2.rundir`: a replay's run directory (the files of a headless run).
- :mod:`app.ros2.compare`: trajectory and object-map differences between a replay and the live run.
- :mod:`app.ros2.errors`: :class:`BagError`, :class:`RecordError` (one clear line each).

Frames follow REP-105: ``map → odom → base_footprint → base_link → {base_scan, camera_link →
camera_optical_frame}``. Stamps are sim time (a run starts at t = 0).
"""
