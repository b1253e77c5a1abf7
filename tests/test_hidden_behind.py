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


def test_a_table_mostly_behind_nearer_boxes_is_hidden_by_them_together():
    """A 1.2 m wide table (0.75 m tall, 3 m ahead) behind chairs 1.5 m ahead, each boxed. No one box covers its image
    columns; with ``covered_share`` 0.5 (``consciousness.hidden_covered_share``) two chairs side by side, or one
    chair over more than half of it, hide it; one chair at its edge (under half) does not; with 1.0 (one box
    covering it whole) none does."""
    cam = default_camera()

    def table(x: float, y: float, w: float = 1.2, d: float = 0.8) -> np.ndarray:
        return np.array([[x - d / 2, y - w / 2], [x + d / 2, y - w / 2], [x + d / 2, y + w / 2], [x - d / 2, y + w / 2]])

    objs, heights = table(3.0, 0.0)[None], np.array([0.75])
    cases = {  # chair centres (y, 1.5 m ahead) → hidden at share 0.5
        (-0.25, 0.25): True,  # side by side, across the whole table
        (0.0,): True,  # one chair in the middle: its box spans over half the table's columns
        (0.62,): False,  # one chair at the table's edge
    }
    for ys, want in cases.items():
        areas = [a for y in ys for a in _areas(cam, [Box(1.5, y, 0.5, 0.5, 0.0, 0.0, 0.95)])]
        assert len(areas) == len(ys)
        assert not hidden_behind(objs, heights, areas, Pose2(), cam, 0.2).any()  # no one box covers it whole
        assert hidden_behind(objs, heights, areas, Pose2(), cam, 0.2, covered_share=0.5).tolist() == [want], ys
