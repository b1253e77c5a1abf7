"""The results table counted on a hand-made map."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.ocslam.evaluation import PAPER_ROW, ObjectReport, evaluate_objects, format_table
from app.ocslam.messages import GroundTruthObject, GroundTruthObstacle, TrackedObject
from app.ocslam.se2 import Pose2


def rect(x, y, sx, sy):
    return np.array([[x - sx / 2, y - sy / 2], [x + sx / 2, y - sy / 2], [x + sx / 2, y + sy / 2], [x - sx / 2, y + sy / 2]])


def truth(i, label, x, y, sx, sy, legged=False):
    return GroundTruthObject(i, label, Pose2(x, y, 0.0), rect(x, y, sx, sy), 0.0, 1.0, legged=legged, name=f"{label}{i}")


def obj(i, label, x, y, p=0.9, source="lidar_island"):
    return TrackedObject(i, label, Pose2(x, y, 0.0), 0.3, 0.3, presence=p, source=source)


TRUTH = [
    truth(0, "table", 0.0, 0.0, 1.8, 1.0, legged=True),
    truth(1, "ball", 3.0, 0.0, 0.22, 0.22),
    truth(2, "door", 5.0, 2.0, 1.0, 0.1),
    truth(3, "chair", 0.0, 3.0, 1.0, 1.8),
    truth(4, "duck", 6.0, -2.0, 0.1, 0.1),
]
OBSTACLES = [GroundTruthObstacle(rect(-3.0, 0.0, 0.7, 0.7), 0.0, 1.8, "obstacle", "fridge"), GroundTruthObstacle(rect(0.0, -3.0, 10.0, 0.2), 0.0, 2.4, "wall")]


def test_counts_on_a_hand_made_map():
    objs = [
        obj(0, "table", 0.1, 0.05),  # TP (error 0.112)
        obj(1, "table", 0.8, 0.4),  # another leg of the same table: FP legs
        obj(2, "table", -0.8, -0.4),  # and another: FP legs
        obj(3, "ball", 3.3, 0.2),  # TP within 0.5 m (error 0.361)
        obj(4, "door", 0.2, 3.3),  # a door label on the chair: FP corner
        obj(5, "shelf", -3.0, 0.1),  # on the fridge (unclassified obstacle): FP corner
        obj(6, "gnome", 2.0, -2.0),  # in free space: FP other
        obj(7, "chair", 0.0, 3.2),  # TP (error 0.2)
        obj(8, "door", 5.0, 2.05, p=0.5),  # below the presence threshold: ignored
        obj(9, "ball", 3.6, 0.9),  # a second ball far from the true one: FP other
    ]
    rep = evaluate_objects(objs, TRUTH, OBSTACLES, presence_threshold=0.8)
    assert (rep.in_scene, rep.in_map, rep.tp, rep.fn) == (5, 9, 3, 2)
    assert (rep.fp_legs, rep.fp_corner, rep.fp_other) == (2, 2, 2)
    assert rep.precision_strict == pytest.approx(3 / 9)
    assert rep.precision_lenient == pytest.approx(5 / 9)
    assert rep.recall == pytest.approx(3 / 5)
    p, r = 3 / 9, 3 / 5
    assert rep.f1 == pytest.approx(2 * p * r / (p + r))
    errs = [np.hypot(0.1, 0.05), np.hypot(0.3, 0.2), 0.2]
    assert rep.pos_err_mean_m == pytest.approx(np.mean(errs))
    assert rep.pos_err_max_m == pytest.approx(max(errs))
    causes = {row["object_id"]: row["cause"] for row in rep.rows if row.get("object_id") is not None}
    assert causes == {0: "tp", 3: "tp", 7: "tp", 1: "legs", 2: "legs", 4: "corner", 5: "corner", 6: "other", 9: "other"}
    missed = sorted(row["class"] for row in rep.rows if row["cause"] == "fn")
    assert missed == ["door", "duck"]
    json.dumps(rep.as_dict())  # serialisable


def test_a_legged_object_is_matched_once_and_the_nearest_object_wins():
    objs = [obj(0, "table", 0.7, 0.3), obj(1, "table", 0.05, 0.0), obj(2, "table", -0.7, 0.3)]
    rep = evaluate_objects(objs, TRUTH[:1], presence_threshold=0.8)
    assert rep.tp == 1 and rep.fp_legs == 2
    (tp_row,) = [r for r in rep.rows if r["cause"] == "tp"]
    assert tp_row["object_id"] == 1


def test_centre_inside_the_footprint_matches_beyond_half_a_metre():
    long_table = [truth(0, "table", 0.0, 0.0, 2.2, 1.0)]
    rep = evaluate_objects([obj(0, "table", 0.9, 0.3)], long_table, presence_threshold=0.8)
    assert rep.tp == 1
    rep = evaluate_objects([obj(0, "table", 1.2, 0.3)], long_table, presence_threshold=0.8)
    assert rep.tp == 0 and rep.fp_legs == 1  # outside, but within touch distance of the table


def test_class_must_match():
    rep = evaluate_objects([obj(0, "gnome", 3.0, 0.0)], TRUTH[1:2], presence_threshold=0.8)
    assert rep.tp == 0 and rep.fn == 1 and rep.fp_corner == 1


def test_perfect_and_empty_maps():
    perfect = [obj(i, t.label, t.pose.x, t.pose.y) for i, t in enumerate(TRUTH)]
    rep = evaluate_objects(perfect, TRUTH, OBSTACLES)
    assert rep.precision_strict == rep.recall == rep.f1 == 1.0
    assert rep.pos_err_max_m == 0.0
    empty = evaluate_objects([], TRUTH, OBSTACLES)
    assert empty.tp == 0 and empty.recall == 0.0 and empty.precision_strict == 0.0
    nothing = evaluate_objects([], [], [])
    assert nothing.precision_strict == 1.0 and nothing.recall == 1.0


def test_paper_row_reproduces_its_precisions():
    r = PAPER_ROW
    assert r["tp"] / r["in_map"] == pytest.approx(r["precision_strict"], abs=0.01)
    assert (r["tp"] + r["fp_legs"]) / r["in_map"] == pytest.approx(r["precision_lenient"], abs=0.01)
    assert r["in_map"] == r["tp"] + r["fp_legs"] + r["fp_corner"] + r["fp_other"]


def test_format_table_prints_both_rows():
    rep = ObjectReport(in_scene=13, in_map=13, tp=13, precision_strict=1.0, precision_lenient=1.0, recall=1.0, f1=1.0, pos_err_mean_m=0.05, pos_err_max_m=0.12)
    text = format_table({"paper": PAPER_ROW, "ours": rep})
    lines = text.splitlines()
    assert len(lines) == 4
    assert lines[2].startswith("paper") and "62 %" in lines[2] and "81 %" in lines[2]
    assert lines[3].startswith("ours") and "100 %" in lines[3] and "0.050" in lines[3]
    assert "–" in lines[2]  # the paper has no F1 or position error
