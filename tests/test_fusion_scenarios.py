"""Scenario tests of the fusion (improved mode) on the kinds of case that broke it on hand-written
worlds (issue 9): chairs pushed against a table, a door faced head-on at a corridor's end, an object in
a room's corner, two same-class neighbours, and one box covering a near and a far object.

Each scene is ray-cast analytically and its boxes are the projections of the true shapes (an oracle
detector, tests/synthetic_scene.py); the assertions are on the objects the map shows.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from synthetic_scene import Box, Cylinder, default_camera, detection, detections, raycast, table

from app.ocslam.config import ConsciousnessConfig
from app.ocslam.consciousness import Consciousness
from app.ocslam.se2 import Pose2

CAM = default_camera()


def make(**kw) -> Consciousness:
    cfg = ConsciousnessConfig()
    for k, v in kw.items():
        setattr(cfg, k, v)
    return Consciousness(cfg, CAM)


def run(c: Consciousness, shapes, labelled, poses, conf: float = 0.9, dt: float = 0.2):
    """One update per pose; ``labelled``: (label, parts) detected whenever its box is in the image."""
    for i, T in enumerate(poses):
        scan = raycast(shapes, T, CAM, noise=0.004, rng=np.random.default_rng(i))
        boxes = [detection(lbl, parts, T, CAM, conf) for lbl, parts in labelled]
        c.update(detections(boxes, CAM), scan, T, stamp=dt * i)


def arc(n: int, cx: float, cy: float, radius: float, a0: float, a1: float):
    """Poses on an arc around ``(cx, cy)`` looking at it."""
    out = []
    for a in np.linspace(a0, a1, n):
        x, y = cx + radius * math.cos(a), cy + radius * math.sin(a)
        out.append(Pose2(x, y, math.atan2(cy - y, cx - x)))
    return out


def straight(n: int, x0: float, y0: float, x1: float, y1: float, yaw: float | None = None):
    yaw = math.atan2(y1 - y0, x1 - x0) if yaw is None else yaw
    return [Pose2(x0 + (x1 - x0) * t, y0 + (y1 - y0) * t, yaw) for t in np.linspace(0.0, 1.0, n)]


def found(c: Consciousness, label: str):
    return [o for o in c.visible_objects() if o.label == label]


def near(objs, x: float, y: float, tol: float = 0.35):
    return [o for o in objs if math.hypot(o.pose.x - x, o.pose.y - y) <= tol]


def chair(x: float, y: float, yaw: float = 0.0, size: float = 0.44, leg: float = 0.03):
    """A dining chair: four thin legs (the LIDAR plane cuts them) and a seat and back above it."""
    c, s = math.cos(yaw), math.sin(yaw)
    legs = []
    h = (size - leg) / 2
    for dx in (-h, h):
        for dy in (-h, h):
            legs.append(Box(x + c * dx - s * dy, y + s * dx + c * dy, leg, leg, yaw, 0.0, 0.45))
    seat = Box(x, y, size, size, yaw, 0.42, 0.47)
    back = Box(x - c * (size / 2 - 0.02), y - s * (size / 2 - 0.02), 0.04, size, yaw, 0.45, 0.9)
    return legs, [seat, back]


def _table_with_chairs(**cfg):
    legs, top = table(3.0, 0.0, 1.8, 1.0)
    chairs = [chair(2.55, -0.62, math.pi / 2), chair(3.45, -0.62, math.pi / 2)]
    shapes = list(legs)
    labelled = [("table", legs + [top])]
    for cl, above in chairs:
        shapes += cl
        labelled.append(("chair", cl + above))
    c = make(**cfg)
    run(c, shapes, labelled, arc(26, 3.0, 0.0, 2.3, -math.pi / 2 - 0.7, -math.pi / 2 + 0.7))
    return c


def test_without_point_ownership_the_chairs_take_the_tables_legs():
    """The former rules (each point to one box by range alone, different classes colliding on their
    footprints): the table loses to the chairs in front of it, which grow over its legs."""
    c = _table_with_chairs(point_ownership=False)
    assert found(c, "table") == []


def test_chairs_pushed_against_a_table_are_found_with_the_table():
    legs, top = table(3.0, 0.0, 1.8, 1.0)
    # two chairs on the near long side, pushed in (their seats under the table's edge)
    chairs = [chair(2.55, -0.62, math.pi / 2), chair(3.45, -0.62, math.pi / 2)]
    shapes = list(legs)
    labelled = [("table", legs + [top])]
    for cl, above in chairs:
        shapes += cl
        labelled.append(("chair", cl + above))
    c = make()
    poses = arc(26, 3.0, 0.0, 2.3, -math.pi / 2 - 0.7, -math.pi / 2 + 0.7)
    run(c, shapes, labelled, poses)
    tables, chs = found(c, "table"), found(c, "chair")
    assert len(tables) == 1 and len(near(tables, 3.0, 0.0, 0.3)) == 1
    assert len(chs) == 2
    assert near(chs, 2.55, -0.62, 0.25) and near(chs, 3.45, -0.62, 0.25)


def test_door_faced_head_on_at_a_corridors_end():
    # corridor 1.4 m wide along x, closed at x = 5 by a wall with a door (a leaf in the wall's plane)
    walls = [Box(2.5, 0.75, 6.0, 0.1, 0, 0, 2.4), Box(2.5, -0.75, 6.0, 0.1, 0, 0, 2.4),
             Box(5.06, 0.6, 0.12, 0.6, 0, 0, 2.4), Box(5.06, -0.6, 0.12, 0.6, 0, 0, 2.4)]
    door = Box(5.02, 0.0, 0.04, 0.9, 0, 0, 2.05)
    c = make()
    run(c, walls + [door], [("door", door)], straight(30, 0.0, 0.0, 3.4, 0.0))
    doors = found(c, "door")
    assert len(doors) == 1
    assert near(doors, 5.02, 0.0, 0.25)


def test_object_in_a_rooms_corner():
    walls = [Box(4.0, 0.0, 0.1, 4.0, 0, 0, 2.4), Box(2.0, 2.0, 4.0, 0.1, 0, 0, 2.4)]
    gnome = Cylinder(3.75, 1.75, 0.12, 0.0, 0.9)
    c = make()
    run(c, walls + [gnome], [("gnome", gnome)], arc(24, 3.75, 1.75, 2.2, -math.pi + 0.5, -math.pi / 2 - 0.1))
    gs = found(c, "gnome")
    assert len(gs) == 1 and near(gs, 3.75, 1.75, 0.15)


def test_two_same_class_neighbours_stay_two():
    # two people talking, shoulder to shoulder 0.55 m apart (legs as pairs of small cylinders)
    def person(x, y):
        return [Cylinder(x, y - 0.09, 0.06, 0.0, 1.75), Cylinder(x, y + 0.09, 0.06, 0.0, 1.75)]

    a, b = person(3.0, -0.3), person(3.0, 0.3)
    c = make()
    poses = straight(24, 0.0, -0.4, 1.2, 0.4, yaw=0.0)
    run(c, a + b, [("person", a), ("person", b)], poses)
    ps = found(c, "person")
    assert len(ps) == 2
    assert near(ps, 3.0, -0.3, 0.2) and near(ps, 3.0, 0.3, 0.2)


def test_a_box_shared_by_a_near_and_a_far_object():
    # an extinguisher in front of a shelf: the shelf's box holds the extinguisher's points too
    wall = Box(4.3, 0.0, 0.1, 6.0, 0, 0, 2.4)
    shelf = Box(4.05, 0.0, 0.4, 1.0, 0, 0, 1.8)
    ext = Cylinder(3.0, 0.2, 0.09, 0.0, 0.7)
    c = make()
    run(c, [wall, shelf, ext], [("shelf", shelf), ("extinguisher", ext)], straight(24, 0.0, -0.6, 0.8, 0.6, yaw=0.0))
    sh, ex = found(c, "shelf"), found(c, "extinguisher")
    assert len(sh) == 1 and near(sh, 4.05, 0.0, 0.25)
    assert len(ex) == 1 and near(ex, 3.0, 0.2, 0.15)


def test_extinguisher_beside_a_partitions_end():
    # a partition (a thin wall) ends at x = 3; the extinguisher stands just past its end
    partition = Box(3.0, 1.0, 0.1, 2.0, 0, 0, 2.0)  # from y = 0 to y = 2
    back = Box(5.0, 0.0, 0.1, 6.0, 0, 0, 2.4)
    ext = Cylinder(3.0, -0.18, 0.09, 0.0, 0.7)
    c = make()
    run(c, [partition, back, ext], [("extinguisher", ext)], straight(24, 0.3, -1.2, 1.2, -0.6, yaw=0.5))
    ex = found(c, "extinguisher")
    assert len(ex) == 1 and near(ex, 3.0, -0.18, 0.15)


def round_table(x: float, y: float, radius: float = 0.5, height: float = 0.74):
    """A round pedestal table: one central column (the LIDAR plane cuts it) under a round top."""
    return [Cylinder(x, y, 0.06, 0.0, height)], [Cylinder(x, y, radius, height - 0.04, height)]


def stool(x: float, y: float, half: float = 0.13):
    """An unclassified stool: four thin legs under a round seat (clutter, never boxed)."""
    legs = [Box(x + dx, y + dy, 0.03, 0.03, 0.0, 0.0, 0.62) for dx in (-half, half) for dy in (-half, half)]
    return legs + [Cylinder(x, y, 0.17, 0.6, 0.64)]


@pytest.mark.parametrize("fraction", [0.8, 0.0])
@pytest.mark.parametrize("where", [(3.3, 0.6), (3.2, 0.9), (3.4, 0.3)])
def test_a_round_table_with_stools_round_its_pedestal(where, fraction: float):
    """A round pedestal table with stools behind it and beside it, approached along one straight stretch (the dev
    world cafe_corner): first seen as one small island on its box's centre line (the stool behind it beyond the
    LIDAR's range), it stands on a pedestal, and the stools' legs that come into range later are not its legs
    (``pedestal_fraction``). Without that rule (and without ``central_support``, which keeps them out view by view)
    the table's footprint swallows the stool behind it."""
    tx, ty = where
    legs, top = round_table(tx, ty)
    shapes = legs + stool(tx + 0.68, ty) + stool(tx, ty + 0.68)
    c = make(pedestal_fraction=fraction, central_support=False)
    run(c, shapes, [("table", legs + top)], straight(40, 0.0, 0.0, 2.0, 0.0))
    tables = found(c, "table")
    assert len(tables) == 1
    assert bool(near(tables, tx, ty, 0.2)) == (fraction > 0.0), (tables[0].pose.x, tables[0].pose.y)


@pytest.mark.parametrize("central", [True, False])
@pytest.mark.parametrize("where", [(3.3, 0.6), (3.4, 0.3), (3.6, 0.7)])
def test_a_round_table_whose_stools_are_in_range_from_the_first_view(where, central: bool):
    """The same table and stools met nearer, so the stools' legs are within the LIDAR's range and inside the table's
    box from the first frame on: every view groups them with the pedestal as the legs of one table, the track never
    learns it stands on a pedestal (``pedestal_fraction``), and its footprint swallows a stool. With
    ``central_support`` the one leg-sized island on the centre line of the much wider box is the pedestal alone in
    each view, so the track learns it (2026-12-06, the dev worlds' round tables among chairs and stools)."""
    tx, ty = where
    legs, top = round_table(tx, ty)
    shapes = legs + stool(tx + 0.68, ty) + stool(tx, ty + 0.68)
    c = make(central_support=central)
    run(c, shapes, [("table", legs + top)], straight(32, 0.8, 0.0, 2.0, 0.0))
    tables = found(c, "table")
    assert len(tables) == 1
    assert bool(near(tables, tx, ty, 0.2)) == central, (tables[0].pose.x, tables[0].pose.y)


@pytest.mark.parametrize("fraction", [0.85, 1.0])
def test_a_box_as_wide_as_the_image_makes_no_object_but_sees_one(fraction: float):
    """A bookcase (1.2 m × 0.35 m, 1.8 m tall) met face-on from 0.9 m: its boxes span the whole image and show none
    of its sides, as the detector's boxes at a wall filling the view do. With ``wide_box_fraction`` they make no
    object (with 1.0, the rule off, they do); the same bookcase approached from 3 m is made by its narrower boxes
    and stays while the wide ones see it."""
    shelf = Box(3.0, 0.0, 0.35, 1.2, 0, 0, 1.8)
    close = straight(12, 1.95, 0.0, 2.15, 0.0)
    T0 = close[0]
    box = detection("shelf", [shelf], T0, CAM, 0.9)
    assert box is not None and (box.x2 - box.x1) >= 0.95 * CAM.info.width  # wide
    c = make(wide_box_fraction=fraction)
    run(c, [shelf], [("shelf", shelf)], close)
    assert len(found(c, "shelf")) == (0 if fraction < 1.0 else 1)

    c = make(wide_box_fraction=fraction)
    run(c, [shelf], [("shelf", shelf)], straight(20, 0.0, 0.0, 2.1, 0.0) + close)
    shelves = found(c, "shelf")
    assert len(shelves) == 1 and near(shelves, 3.0, 0.0, 0.3)


@pytest.mark.parametrize("whole_only", [True, False])
def test_a_fragment_is_not_confirmed_by_boxes_that_fill_the_view(whole_only: bool):
    """A 1.2 m surface 1 m away (a counter the detector takes for a bookcase), glimpsed in two frames through boxes cut
    by the image's left border while the robot turns towards it, then filling the view: the cut boxes make a fragment,
    and boxes as wide as the image show no more of it than a wall would. With ``wide_box_whole_only`` they do not
    confirm a fragment, so it never reaches the map; without, they do (the narrow galley's counter, 2026-12-07).
    An object seen whole before is still confirmed by them (``test_a_box_as_wide_as_the_image_makes_no_object_but_sees_one``)."""
    counter = Box(3.0, 0.0, 0.35, 1.2, 0, 0, 1.8)
    poses = [Pose2(1.95, 0.0, yaw) for yaw in [-0.9, -0.75] + list(np.linspace(-0.15, 0.0, 8))]
    cols = [detection("shelf", [counter], T, CAM, 0.9) for T in poses]
    assert all(b is not None and b.x1 <= 0.0 for b in cols)  # every box cut by the left border
    assert all((b.x2 - b.x1) < 0.85 * CAM.info.width for b in cols[:2])
    assert all((b.x2 - b.x1) >= 0.85 * CAM.info.width for b in cols[2:])
    c = make(wide_box_whole_only=whole_only)
    run(c, [counter], [("shelf", counter)], poses)
    assert len(found(c, "shelf")) == (0 if whole_only else 1)
