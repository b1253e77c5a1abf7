"""The oracle detector on a tiny rendered scene: right classes and boxes, visibility test, noise, errors."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from app.config import Config
from app.ocslam.config import DetectorConfig
from app.ocslam.detector import DetectorError
from app.ocslam.messages import CLASS_INDEX
from app.ocslam.se2 import Pose2
from app.training.oracle import OracleDetector


@pytest.fixture(scope="module")
def scene():
    from app.sim_world import SimWorld
    from app.world.types import World, WorldObject

    world = World(
        name="tiny",
        objects=[
            WorldObject("ball", "play_ball", 2.0, 0.25),  # fully visible
            WorldObject("duck", "rubber_duck", 3.2, 0.57),  # partly behind the ball: 29 px visible
            WorldObject("ball", "play_ball", 2.0, -1.15),  # 30 % inside the right edge
            WorldObject("extinguisher", "fire_extinguisher", 2.5, 0.9),  # fully visible
        ],
    )
    with SimWorld(world, Config()) as sim:
        frame = sim.render_view(Pose2(0.0, 0.0, 0.0), width=320, height=240, camera_z=0.11, segmentation=True)
        yield world, frame, sim.ground_truth_objects()


def exact_cfg(**kw) -> DetectorConfig:
    return replace(
        DetectorConfig(),
        oracle_confidence_std=0.0,
        oracle_box_jitter_px=0.0,
        oracle_min_pixels=40,
        oracle_min_visible_fraction=0.35,
        **kw,
    )


def test_oracle_boxes_are_the_visible_boxes(scene) -> None:
    world, frame, gt = scene
    from app.training.labels import visible_boxes

    vis = visible_boxes(frame.segmentation)
    dets = OracleDetector(exact_cfg(), np.random.default_rng(0), world=world).detect(frame, gt)
    assert (dets.image_width, dets.image_height) == (320, 240)
    got = {d.class_id: d for d in dets.boxes}
    # The small duck (under 40 px) and the truncated ball (30 % < 35 % visible) are not reported.
    assert sorted(got) == sorted([CLASS_INDEX["ball"], CLASS_INDEX["extinguisher"]])
    ball = got[CLASS_INDEX["ball"]]
    assert (ball.x1, ball.y1, ball.x2, ball.y2) == vis[0][:4]
    assert ball.confidence == pytest.approx(0.85)
    assert dets.boxes[0].confidence >= dets.boxes[-1].confidence


def test_without_the_world_only_pixels_count(scene) -> None:
    _, frame, gt = scene
    dets = OracleDetector(exact_cfg(), np.random.default_rng(0)).detect(frame, gt)
    assert sum(d.class_id == CLASS_INDEX["ball"] for d in dets.boxes) == 2


def test_threshold_ignore_and_noise(scene) -> None:
    world, frame, gt = scene
    assert len(OracleDetector(exact_cfg(confidence=0.9), np.random.default_rng(0), world).detect(frame, gt)) == 0
    only = OracleDetector(exact_cfg(ignore_classes=["ball"]), np.random.default_rng(0), world).detect(frame, gt)
    assert [d.label for d in only.boxes] == ["extinguisher"]
    noisy_cfg = replace(exact_cfg(), oracle_box_jitter_px=2.0, oracle_confidence_std=0.05)
    a = OracleDetector(noisy_cfg, np.random.default_rng(3), world).detect(frame, gt)
    b = OracleDetector(noisy_cfg, np.random.default_rng(3), world).detect(frame, gt)
    exact = OracleDetector(exact_cfg(), np.random.default_rng(0), world).detect(frame, gt)
    assert a == b  # seeded
    assert a.yolo_boxes().shape == exact.yolo_boxes().shape
    diffs = np.abs(a.yolo_boxes()[:, :4] - exact.yolo_boxes()[:, :4])
    assert diffs.max() > 0 and diffs.max() < 12  # jittered by a few pixels


def test_frame_without_segmentation_is_a_clear_error(scene) -> None:
    world, frame, gt = scene
    bare = replace(frame, segmentation=None)
    with pytest.raises(DetectorError, match="segmentation"):
        OracleDetector(DetectorConfig(), np.random.default_rng(0), world).detect(bare, gt)
