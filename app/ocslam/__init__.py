"""The algorithm core: odometry, SLAM, detector, projection, consciousness, evaluation.

Pure and typed: no pybullet or viser imports here. Inputs and outputs are the message dataclasses
of :mod:`app.ocslam.messages`, stamped with sim time.
"""
