"""Ghost decay: an object the camera cannot see behind a nearer object's box is not missed in clear view
(``ghosts.hidden_behind``, ``consciousness.hidden_behind_boxes``)."""

from __future__ import annotations

import numpy as np

from app.ocslam.ghosts import hidden_behind
from app.ocslam.projection import bounding_areas
from app.ocslam.se2 import Pose2
from tests.synthetic_scene import Box, default_camera, detection, detections


def _areas(cam, parts, label: str = "chair"):
    return bounding_areas(detections([detection(label, parts, Pose2(), cam)], cam), cam, 8.0, 2.0, 2.0, 0.2)


def test_an_object_behind_a_nearer_objects_box_is_hidden_and_one_in_front_or_beside_it_is_not():
    """A chair (a solid 0.5 × 0.5 × 0.9 m block, 1.5 m ahead) boxed: a 0.2 m extinguisher 0.5 m tall 3 m ahead is
    hidden by it; the same 1.0 m ahead (in front of the chair), 3 m ahead but 1 m to the side (outside the box), or
    a 1.8 m person 3 m ahead (its head above the box) is not; nor is anything when no box is nearer."""
    cam = default_camera()
    chair = [Box(1.5, 0.0, 0.5, 0.5, 0.0, 0.0, 0.9)]
    areas = _areas(cam, chair)
    assert len(areas) == 1

    def corners(x: float, y: float, s: float = 0.2) -> np.ndarray:
        return np.array([[x - s / 2, y - s / 2], [x + s / 2, y - s / 2], [x + s / 2, y + s / 2], [x - s / 2, y + s / 2]])

    objs = np.stack([corners(3.0, 0.0), corners(1.0, 0.0), corners(3.0, 1.0), corners(3.0, 0.0, 0.4)])
    heights = np.array([0.5, 0.5, 0.5, 1.8])
    got = hidden_behind(objs, heights, areas, Pose2(), cam, 0.2)
    assert got.tolist() == [True, False, False, False]
    far_chair = _areas(cam, [Box(4.0, 0.0, 0.5, 0.5, 0.0, 0.0, 0.9)])
    assert not hidden_behind(objs[:1], heights[:1], far_chair, Pose2(), cam, 0.2).any()  # the box's object is behind it
    assert not hidden_behind(objs, heights, [], Pose2(), cam, 0.2).any()
