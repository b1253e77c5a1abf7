"""OCSLAM: Object-Conscious SLAM with YOLO and a 2D LIDAR, in a pybullet apartment, live in viser."""

__version__ = "0.1.0"
