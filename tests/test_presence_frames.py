"""The soft decision's ``F`` for an object the robot turns past (issue 9, improved mode).

The paper's presence ``c·f/F`` needs ``F`` = 5 frames; an object passed during a 1.5 rad/s turn at 5 Hz is in
view for two to four. With ``min_frames_for_presence`` the denominator is the frames the object *could* have
been seen in (those that boxed it and its clear misses), clipped to ``[min, F]``."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from synthetic_scene import Cylinder
from test_fusion_scenarios import found, make, run

from app.ocslam.candidate import Candidate
from app.ocslam.config import ConsciousnessConfig
from app.ocslam.footprint import Footprint
from app.ocslam.se2 import Pose2
from app.ocslam.tracks import create_track, presence_frames, update_track


def _cand(conf: float = 0.9) -> Candidate:
    pts = np.array([[2.0, 0.0], [2.05, 0.05], [2.0, 0.1]])
    return Candidate(0, "extinguisher", conf, "lidar_island", pts, Footprint(pts.mean(axis=0), 0.0, 0.18, 0.18), 2.0,
                     ray_origin=np.zeros(2), ray_dir=np.array([1.0, 0.0]), ray_weight=1.0)


def _track_over(frames: int, misses: int, cfg: ConsciousnessConfig, conf: float = 0.9):
    """Created, then ``misses`` clear misses, then boxed in ``frames - 1`` more moving frames."""
    t = create_track(0, _cand(conf), 0.0, -1, cfg, None)
    t.misses += misses
    for i in range(1, frames):
        update_track(t, _cand(conf), 0.2 * i, -1, True, cfg, None)
    return t


def test_known_answers():
    cfg = ConsciousnessConfig()
    assert cfg.frames_for_presence == 5 and cfg.min_frames_for_presence == 3
    # boxed in each of its three frames, never missed: judged on three frames, so it reaches its confidence
    assert _track_over(3, 0, cfg).presence == 0.9
    # missed twice in clear view after its first frame: five frames it could have been seen in, three boxed it
    assert math.isclose(_track_over(3, 2, cfg).presence, 0.9 * 3 / 5)
    # one frame only: 0.9 / 3, below the paper's 80 %
    assert math.isclose(create_track(0, _cand(), 0.0, -1, cfg, None).presence, 0.3)
    paper = ConsciousnessConfig()
    paper.min_frames_for_presence = 0
    assert math.isclose(_track_over(3, 0, paper).presence, 0.9 * 3 / 5)  # the paper's c·f/F
    assert math.isclose(create_track(0, _cand(), 0.0, -1, paper, None).presence, 0.9 / 5)


@settings(max_examples=60, deadline=None)
@given(frames=st.integers(1, 9), misses=st.integers(0, 6), m=st.integers(0, 8), conf=st.floats(0.05, 1.0))
def test_presence_is_between_the_papers_and_the_confidence(frames, misses, m, conf):
    cfg = ConsciousnessConfig()
    cfg.min_frames_for_presence = m
    paper = ConsciousnessConfig()
    paper.min_frames_for_presence = 0
    t = _track_over(frames, misses, cfg, conf)
    p_paper = _track_over(frames, misses, paper, conf).presence
    assert p_paper - 1e-12 <= t.presence <= conf + 1e-12
    assert 1 <= presence_frames(t, cfg) <= cfg.frames_for_presence
    if m == 0 or m >= cfg.frames_for_presence:
        assert t.presence == p_paper


def test_an_object_passed_in_a_fast_turn_is_found():
    """An in-place turn at 1.3 rad/s, 5 Hz: the extinguisher is in view for four frames."""
    ext = Cylinder(2.2, 0.0, 0.09, 0.0, 0.77)
    poses = [Pose2(0.0, 0.0, float(a)) for a in np.arange(-1.5, 1.51, 0.26)]
    paper = make(min_frames_for_presence=0)
    run(paper, [ext], [("extinguisher", ext)], poses, conf=0.95)
    assert not found(paper, "extinguisher")  # the paper's F = 5 frames never came
    ours = make()
    run(ours, [ext], [("extinguisher", ext)], poses, conf=0.95)
    objs = found(ours, "extinguisher")
    assert len(objs) == 1 and math.hypot(objs[0].pose.x - 2.2, objs[0].pose.y) < 0.15


def test_presence_sequence_of_an_object_boxed_in_every_frame():
    """Driving past a ball boxed in each frame, never missed, with ``min_frames_for_presence`` 3: c/3, 2c/3, then
    c (the paper: c/5 … c at 5), at most the presence evidence of three boxes (odds 1.8³: 0.854) at the third."""
    from synthetic_scene import Box, detection, detections, raycast
    from test_consciousness import line

    ball = Cylinder(2.0, 0.05, 0.11, 0.0, 0.22)
    wall = Box(3.3, 0.0, 0.2, 6.0, 0.0, 0.0, 2.4)
    c = make(min_frames_for_presence=3)
    seq = []
    for i, T in enumerate(line(6)):
        c.update(detections([detection("ball", ball, T, c.camera, 0.9)], c.camera), raycast([ball, wall], T, c.camera), T,
                 stamp=0.2 * i)
        (o,) = c.objects
        seq.append(round(o.presence, 6))
    assert seq == pytest.approx([0.3, 0.6, 1.8**3 / (1 + 1.8**3), 0.9, 0.9, 0.9], abs=1e-6)


def test_judged_on_fewer_frames_the_mean_confidence_counts():
    """Four frames, never missed, judged on at least four (``F' = 4``): ``Y_c`` is the frames' mean, not the best box
    alone: 0.8375, where the paper (``F = 5``, best box) gives 0.76 and the best box alone would give 0.95."""
    cfg = ConsciousnessConfig()
    cfg.min_frames_for_presence = 4
    confs = [0.95, 0.95, 0.95, 0.5]
    t = create_track(0, _cand(confs[0]), 0.0, -1, cfg, None)
    for i, c in enumerate(confs[1:], start=1):
        update_track(t, _cand(c), 0.2 * i, -1, True, cfg, None)
    assert t.presence == pytest.approx(sum(confs) / 4)
    paper = ConsciousnessConfig()
    paper.min_frames_for_presence = 0
    tp = create_track(0, _cand(confs[0]), 0.0, -1, paper, None)
    for i, c in enumerate(confs[1:], start=1):
        update_track(tp, _cand(c), 0.2 * i, -1, True, paper, None)
    assert tp.presence == pytest.approx(0.95 * 4 / 5)
