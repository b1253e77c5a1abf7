"""KeyframeAnchors: the keyframes evidence is tagged with, and their motions under SLAM corrections."""

from __future__ import annotations

import math

import pytest

from app.ocslam.evidence import NO_KEYFRAME
from app.ocslam.keyframe_anchors import KeyframeAnchors
from app.ocslam.se2 import Pose2


def test_attach_new_known_and_moved_keyframes():
    a = KeyframeAnchors()
    assert a.attach(None) == (NO_KEYFRAME, {})
    assert a.attach((3, Pose2(float("nan"), 0.0, 0.0))) == (NO_KEYFRAME, {})
    assert a.attach((3, Pose2(1.0, 0.0, 0.0))) == (3, {})
    assert a.attach((3, Pose2(1.0, 0.0, 0.0))) == (3, {})  # the same pose: no motion
    k, d = a.attach((3, Pose2(1.0, 0.5, math.pi / 2)))
    assert k == 3 and set(d) == {3}
    # the motion carries the old keyframe pose onto the new one
    moved = d[3] @ Pose2(1.0, 0.0, 0.0)
    assert (moved.x, moved.y, moved.yaw) == pytest.approx((1.0, 0.5, math.pi / 2))
    assert a.poses[3] == Pose2(1.0, 0.5, math.pi / 2)


def test_correct_moves_known_keyframes_only():
    a = KeyframeAnchors({1: Pose2(0.0, 0.0, 0.0), 2: Pose2(2.0, 0.0, 0.0), 4: Pose2(4.0, 0.0, 0.0)})
    new = {1: Pose2(0.0, 0.0, 0.0), 2: Pose2(2.0, 0.3, 0.0), 4: None}
    deltas = a.correct(lambda k: new[k])
    assert set(deltas) == {2}  # 1 did not move, 4 has no new pose
    assert (deltas[2].x, deltas[2].y) == pytest.approx((0.0, 0.3))
    assert a.poses[4] == Pose2(4.0, 0.0, 0.0)
    assert a.correct(lambda k: (_ for _ in ()).throw(KeyError(k))) == {}  # unknown to SLAM: kept
