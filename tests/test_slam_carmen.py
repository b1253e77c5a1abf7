"""The CARMEN reader on hand-made excerpts (180 and 360 beams, PARAM offset, ODOM vs FLASER odometry)."""

from __future__ import annotations

import bz2
import math
from pathlib import Path

import numpy as np
import pytest

from app.ocslam.slam.carmen import CarmenError, beam_layout, read_carmen

DATA = Path(__file__).parent / "data" / "carmen"


def test_beam_rule():
    assert beam_layout(180) == (-math.pi / 2, math.radians(1.0))
    assert beam_layout(181) == (-math.pi / 2, math.radians(1.0))
    assert beam_layout(361) == (-math.pi / 2, math.radians(0.5))
    assert beam_layout(401) == (-math.pi / 2, math.radians(0.25))
    assert beam_layout(90) == (-math.pi / 2, math.pi / 90)
    with pytest.raises(CarmenError):
        beam_layout(0)


def test_180_beams_with_odom_lines_and_offset():
    log = read_carmen(DATA / "excerpt_180.log")
    assert len(log) == 2  # the malformed FLASER line is skipped
    assert log.T_base_scan.x == pytest.approx(0.25) and log.T_base_scan.y == 0.0
    assert log.max_range == pytest.approx(81.83)
    s0 = log.scan(0)
    assert len(s0.ranges) == 180
    assert s0.angle_min == pytest.approx(-math.pi / 2) and s0.angle_increment == pytest.approx(math.radians(1))
    assert s0.angles[90] == pytest.approx(0.0)
    assert np.isinf(s0.ranges[90])  # max range: no return
    assert s0.ranges[0] == 2.5 and s0.ranges[179] == 0.5
    # first beam points to the robot's right (−y)
    p = s0.points()
    assert p[0, 0] == pytest.approx(0.0, abs=1e-12) and p[0, 1] == pytest.approx(-2.5)
    # odometry interpolated from the ODOM lines at the FLASER stamps (not the FLASER pose)
    assert np.allclose(log.odom[0], [0.5, 0.0, 0.1])
    assert np.allclose(log.odom[1], [1.0, 0.0, 0.2])
    assert np.allclose(log.flaser_odom[1], [9.0, 9.0, 0.2])
    assert log.stamps.tolist() == [100.5, 101.0]


def test_360_beams_flaser_pose_when_no_odom(tmp_path):
    raw = (DATA / "excerpt_360.log").read_bytes()
    p = tmp_path / "x.clf.bz2"
    p.write_bytes(bz2.compress(raw))
    log = read_carmen(p)
    assert len(log) == 3
    assert log.T_base_scan.x == 0.0
    s = log.scan(1)
    assert len(s.ranges) == 360 and s.angle_increment == pytest.approx(math.radians(0.5))
    assert s.angles[-1] == pytest.approx(math.radians(89.5))
    assert np.isinf(s.ranges[359]) and s.ranges[358] == pytest.approx(4.58)
    assert np.allclose(log.odom, [[0.5, 0.1, 0.05], [0.6, 0.1, 0.06], [0.7, 0.2, 0.07]])
    assert log.duration == pytest.approx(0.4)


def test_errors(tmp_path):
    with pytest.raises(CarmenError):
        read_carmen(tmp_path / "missing.clf")
    bad = tmp_path / "bad.clf"
    bad.write_text("ODOM 0 0 0 0 0 0 1.0 nohost 0\nnonsense\n")
    with pytest.raises(CarmenError, match="no FLASER"):
        read_carmen(bad)
