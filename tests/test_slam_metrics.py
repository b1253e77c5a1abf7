"""The relation metric, ATE and map agreement against hand computations."""

from __future__ import annotations

import numpy as np
import pytest

from app.ocslam.messages import OccupancyGrid
from app.ocslam.se2 import Pose2
from app.ocslam.slam.metrics import Relations, ate_rmse, map_agreement, read_relations, relation_errors


def test_relation_metric_hand_computed(tmp_path):
    stamps = np.array([0.0, 1.0, 2.0])
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, np.pi / 2], [1.0, 1.0, np.pi / 2]])
    # estimated motions: 0→1 = (1, 0, 90°); 1→2 = R(-90°)(0, 1) = (1, 0, 0°); 0→2 = (1, 1, 90°)
    text = (
        "0.0 1.0 1.1 0.0 0 0 0 1.6707963267948966\n"  # errors: 0.1 m, 0.1 rad
        "1.0 2.0 1.0 0.2 0 0 0 0.0\n"  # errors: 0.2 m, 0
        "0.0 2.0 1.0 1.0 0 0 0 1.3707963267948966\n"  # errors: 0, 0.2 rad
        "garbage line\n"
    )
    p = tmp_path / "x.relations"
    p.write_text(text)
    rel = read_relations(p)
    assert len(rel) == 3
    err = relation_errors(stamps, poses, rel)
    assert np.allclose(err.trans, [0.1, 0.2, 0.0], atol=1e-12)
    assert np.allclose(err.rot, [0.1, 0.0, 0.2], atol=1e-12)
    s = err.summary()
    assert s["relations"] == 3
    assert s["trans_mean_m"] == pytest.approx(0.1)
    assert s["trans_std_m"] == pytest.approx(np.std([0.1, 0.2, 0.0]))
    assert s["trans_sq_mean_m2"] == pytest.approx((0.01 + 0.04) / 3)
    assert s["rot_mean_deg"] == pytest.approx(np.degrees(0.1))
    assert s["rot_sq_mean_deg2"] == pytest.approx((np.degrees(0.1) ** 2 + np.degrees(0.2) ** 2) / 3)


def test_relation_metric_interpolates_between_stamps():
    stamps = np.array([0.0, 2.0])
    poses = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    rel = Relations(np.array([0.0]), np.array([1.0]), np.array([[1.0, 0.0, 0.0]]))
    err = relation_errors(stamps, poses, rel)
    assert err.trans[0] == pytest.approx(0.0) and err.rot[0] == pytest.approx(0.0)


def test_rotation_error_wraps():
    stamps = np.array([0.0, 1.0])
    poses = np.array([[0.0, 0.0, 3.1], [0.0, 0.0, -3.1]])
    rel = Relations(np.array([0.0]), np.array([1.0]), np.array([[0.0, 0.0, 0.0]]))
    err = relation_errors(stamps, poses, rel)
    assert err.rot[0] == pytest.approx(2 * np.pi - 6.2)


def test_ate_rmse():
    est = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 0.0]])
    gt = np.array([[0.3, 0.4, 1.0], [1.0, 1.0, 0.0]])
    assert ate_rmse(est, gt) == pytest.approx(np.sqrt(0.25 / 2))
    with pytest.raises(ValueError):
        ate_rmse(est, gt[:1])


def test_map_agreement_hand_made():
    # 10×10 grid at 0.1 m; the true obstacle is the square [0.21, 0.49]²  → cells 2..4
    data = np.full((10, 10), 0, np.int8)
    data[2, 2:5] = 100  # the wall's bottom edge, seen
    data[8, 8] = 100  # a false obstacle far away
    g = OccupancyGrid(0.1, Pose2(0.0, 0.0, 0.0), data)
    poly = np.array([[0.21, 0.21], [0.49, 0.21], [0.49, 0.49], [0.21, 0.49]])
    prec, rec = map_agreement(g, [poly])
    assert prec == pytest.approx(3 / 4)
    # boundary cells of the 3×3 true block: 8; within one cell of an occupied cell (rows 1..3):
    # (2,2) (2,3) (2,4) (3,2) (3,4) → 5 of 8
    assert rec == pytest.approx(5 / 8)
    # unobserved boundary cells do not count against recall
    data2 = data.copy()
    data2[4:, :] = -1
    _, rec2 = map_agreement(OccupancyGrid(0.1, Pose2(0.0, 0.0, 0.0), data2), [poly])
    # row 4 unknown but within one cell of observed row 3, so still counted: 5 of 8 again
    assert rec2 == pytest.approx(5 / 8)
    data3 = data.copy()
    data3[3:, :] = -1
    _, rec3 = map_agreement(OccupancyGrid(0.1, Pose2(0.0, 0.0, 0.0), data3), [poly])
    # only rows 2..3 of the boundary are observed or next to observed cells: 5 cells, all found
    assert rec3 == pytest.approx(1.0)
