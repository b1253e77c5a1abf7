"""The camera-view test of ghost decay: known answers, and the batched form against its definition."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from synthetic_scene import default_camera

from app.ocslam.footprint import Footprint
from app.ocslam.presence import centers_in_camera_view, in_camera_view
from app.ocslam.se2 import Pose2

CAM = default_camera()


def _view(x: float, y: float, height: float = 0.8, max_range: float = 4.0, T_map_base: Pose2 = Pose2(0, 0, 0)) -> bool:
    return in_camera_view(Footprint(np.array([x, y]), 0.0, 0.3, 0.3), height, T_map_base, CAM, max_range)


def test_known_answers():
    assert _view(2.0, 0.0)                  # straight ahead
    assert not _view(-2.0, 0.0)             # behind the robot
    assert not _view(5.0, 0.0)              # beyond the decay range
    assert not _view(1.0, 2.0)              # far outside the horizontal field of view (±30°)
    assert not _view(0.01, 0.0)             # at the camera: not in front of it
    # the robot's pose: an object 2 m along +y of the map is ahead of a robot facing +y
    assert _view(0.0, 2.0, T_map_base=Pose2(0, 0, np.pi / 2))
    assert not _view(2.0, 0.0, T_map_base=Pose2(0, 0, np.pi / 2))


def test_margin_of_the_image_is_excluded():
    # a centre projecting into the outer 8 % columns is not "in clear view"
    half_fov = 0.5 * 1.04
    edge = 2.0 * np.tan(half_fov * 0.97)
    assert not _view(2.0, edge)
    assert _view(2.0, 2.0 * np.tan(half_fov * 0.5))


@settings(max_examples=60, deadline=None)
@given(
    pts=st.lists(st.tuples(st.floats(-6, 6), st.floats(-6, 6), st.floats(0.05, 2.5)), min_size=1, max_size=25),
    pose=st.tuples(st.floats(-3, 3), st.floats(-3, 3), st.floats(-np.pi, np.pi)),
    max_range=st.floats(0.5, 6.0),
)
def test_batch_agrees_with_one_by_one(pts, pose, max_range):
    T_map_base = Pose2(*pose)
    centers = np.array([(x, y) for x, y, _ in pts])
    heights = np.array([h for _, _, h in pts])
    batch = centers_in_camera_view(centers, heights, T_map_base.inverse(), CAM, max_range)
    assert batch.tolist() == [_reference(c, h, T_map_base, max_range) for c, h in zip(centers, heights)]


def _reference(c, h, T_map_base: Pose2, max_range: float) -> bool:
    """The definition, one object at a time: its mid-height centre in the inner 84 % of the columns,
    inside the rows, in front of the camera and within range of it."""
    cb = T_map_base.inverse().transform_points(np.asarray(c)[None, :])[0]
    uv, depth = CAM.project(np.array([[cb[0], cb[1], min(max(h / 2, 0.02), 1.0)]]))
    if not depth[0] > 0.05:
        return False
    W, H = CAM.info.width, CAM.info.height
    u, v = uv[0]
    return bool(0.08 * W <= u <= 0.92 * W and 0 <= v <= H and np.hypot(*(cb - CAM.center_base[:2])) <= max_range)


# -- how much of an object the image holds (clear misses follow the detector's labelling rule) ------------


def _square(x: float, y: float, half: float) -> np.ndarray:
    return np.array([[x - half, y - half], [x + half, y - half], [x + half, y + half], [x - half, y + half]])


def test_in_frame_fractions_known_answers():
    from app.ocslam.presence import in_frame_boxes

    def in_frame_fractions(*a):
        return in_frame_boxes(*a)[0]

    cam = default_camera()
    hfov = 2.0 * math.atan(cam.info.width / (2.0 * cam.info.fx)) if hasattr(cam.info, "fx") else 1.04
    edge = 0.5 * hfov  # a thin object whose centre column is the image's left edge
    corners = np.stack([
        _square(2.0, 0.0, 0.05),                                          # small, straight ahead
        _square(2.0 * math.cos(edge), 2.0 * math.sin(edge), 0.02),        # half out at the left edge
        _square(-2.0, 0.0, 0.1),                                          # behind the robot
        _square(0.0, 0.0, 1.0),                                           # the robot inside it
        _square(3.0, 5.0, 0.1),                                           # far out to the left
    ])
    f = in_frame_fractions(corners, np.array([0.3, 0.3, 0.3, 0.3, 0.3]), Pose2(), cam)
    assert f[0] == pytest.approx(1.0)
    assert 0.35 < f[1] < 0.65
    assert f[2] == 0.0 and f[3] == 0.0 and f[4] == 0.0
    # a tall object seen close: its top leaves the frame, less than half of its box is inside
    tall = in_frame_fractions(_square(1.0, 0.0, 0.05)[None], np.array([2.5]), Pose2(), cam)[0]
    assert tall < 0.5
    assert in_frame_fractions(np.zeros((0, 4, 2)), np.zeros(0), Pose2(), cam).shape == (0,)


def test_a_table_filling_the_frame_is_not_a_clear_miss():
    """A 2 m table 0.6 m ahead fills more than the frame: a frame without its box is not a miss (the detector's
    labels leave out objects less than half in the frame); with the centre test alone (0) it is."""
    from synthetic_scene import detection, detections, raycast, table

    from app.ocslam.config import ConsciousnessConfig
    from app.ocslam.consciousness import Consciousness

    cam = default_camera()
    legs, top = table(2.9, 0.0, length=1.0, width=2.0)
    counts = {}
    for share in (0.5, 0.0):
        cfg = ConsciousnessConfig()
        cfg.clear_view_in_frame = share
        c = Consciousness(cfg, cam)
        for i in range(6):  # boxed from 2.9–2.7 m, the whole table in view
            T = Pose2(0.04 * i, 0.0, 0.0)
            c.update(detections([detection("table", legs + [top], T, cam, 0.9)], cam), raycast(legs + [top], T, cam), T,
                     stamp=0.2 * i)
        (t,) = c._tracks
        for i in range(5):  # then 0.6 m from it, no box
            T = Pose2(1.8, 0.0, 0.0)
            c.update(detections([], cam), raycast(legs + [top], T, cam), T, stamp=1.2 + 0.2 * i)
        counts[share] = t.misses
    assert counts[0.5] == 0 and counts[0.0] == 5


# --- visible_share: what the LIDAR sees of an object, and what may go on behind a nearer return --------------


def _beams(step_deg: float = 0.5) -> np.ndarray:
    return np.deg2rad(np.arange(-180.0, 180.0, step_deg))


def _share(ranges: np.ndarray, extent: float = 0.5, fp: Footprint | None = None) -> float:
    from app.ocslam.presence import visible_share

    fp = fp if fp is not None else Footprint(np.array([2.0, 0.0]), 0.0, 0.2, 0.2)
    return visible_share(fp, Pose2(0, 0, 0), _beams(), ranges, 0.2, extent)


def test_visible_share_known_answers():
    b = _beams()
    free = np.full(len(b), 5.0)            # a wall 5 m away: nothing in front of the object
    assert _share(free) == pytest.approx(1.0)
    # a stub 1 m away right beside the object's left edge, 0.3 m wide: the object may go on behind it
    span = math.atan2(0.1, 1.9)             # the footprint's half-span seen from the origin (nearest face)
    stub = free.copy()
    stub[(b > span) & (b <= span + math.atan2(0.15, 1.0))] = 1.0
    s = _share(stub)
    assert 0.3 < s < 0.7                    # the span's beams all reach it, but as many may be hidden
    assert _share(stub, extent=0.0) == pytest.approx(1.0)   # an object known to end at its footprint
    # the same stub 0.3 m to the side, not touching the span: nothing is hidden
    away = free.copy()
    away[(b > span + 0.1) & (b <= span + 0.2)] = 1.0
    assert _share(away) == pytest.approx(1.0)
    # the object's own span blocked: not seen at all
    wall = free.copy()
    wall[np.abs(b) < 0.3] = 1.0
    assert _share(wall) == pytest.approx(0.0)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), extent=st.floats(0.0, 2.0), x=st.floats(0.8, 4.0), y=st.floats(-2.0, 2.0))
def test_visible_share_is_a_share_and_shrinks_with_the_extent(seed, extent, x, y):
    rng = np.random.default_rng(seed)
    r = np.repeat(rng.uniform(0.2, 6.0, 72), 10)   # 72 surfaces of 5° each
    fp = Footprint(np.array([x, y]), 0.3, 0.4, 0.25)
    s = _share(r, extent, fp)
    assert 0.0 <= s <= 1.0
    assert _share(r, extent + 0.5, fp) <= s + 1e-12   # a longer possible object hides at least as much


def test_in_frame_boxes_sides_shrink_with_range():
    """The smaller side of an object's image box halves when its distance doubles, and is 0 behind the camera."""
    from app.ocslam.presence import in_frame_boxes

    cam = default_camera()
    corners = np.stack([_square(1.5, 0.0, 0.05), _square(3.0, 0.0, 0.05), _square(-2.0, 0.0, 0.05)])
    frac, side = in_frame_boxes(corners, np.array([0.1, 0.1, 0.1]), Pose2(), cam)
    assert frac[0] == pytest.approx(1.0) and frac[1] == pytest.approx(1.0)
    assert side[0] / side[1] == pytest.approx(2.0, rel=0.15)
    assert side[2] == 0.0 and frac[2] == 0.0
    # the width of a 0.1 m object whose near face is 1.45 m ahead: fx·0.1/1.45 pixels
    assert side[0] == pytest.approx(float(np.asarray(cam.info.K).reshape(3, 3)[0, 0]) * 0.1 / 1.45, rel=0.02)


def test_a_duck_that_looks_small_is_not_a_clear_miss():
    """A duck boxed from close by, then in view 2.4 m away without a box: its image box is ~12 px (in the detector's
    320-px input) — the detector boxes about half of such objects, so those frames are no clear misses at
    ``clear_view_min_px: 20``; with 0 every one is."""
    from synthetic_scene import Box, detection, detections, raycast

    from app.ocslam.config import ConsciousnessConfig
    from app.ocslam.consciousness import Consciousness

    cam = default_camera()
    duck = Box(3.2, 0.0, 0.11, 0.11, 0.0, 0.0, 0.1)
    wall = Box(5.0, 0.0, 0.1, 6.0, 0.0, 0.0, 2.0)
    counts = {}
    for min_px in (20.0, 0.0):
        cfg = ConsciousnessConfig()
        cfg.clear_view_min_px = min_px
        c = Consciousness(cfg, cam)
        for i in range(6):  # boxed from 1.2–1.0 m
            T = Pose2(2.0 + 0.04 * i, 0.0, 0.0)
            c.update(detections([detection("duck", duck, T, cam, 0.9)], cam), raycast([duck, wall], T, cam), T, stamp=0.2 * i)
        (t,) = [t for t in c._tracks if t.label == "duck"]
        for i in range(5):  # then 2.4 m from it, in view, no box
            T = Pose2(0.8, 0.0, 0.0)
            c.update(detections([], cam), raycast([duck, wall], T, cam), T, stamp=1.2 + 0.2 * i)
        counts[min_px] = t.misses
    assert counts[20.0] == 0 and counts[0.0] == 5


@pytest.mark.parametrize("own_points", [True, False])
def test_flowers_against_the_far_side_of_a_partition_are_not_missed_through_it(own_points):
    """Flowers stand against a thin partition, boxed from their open side; their footprint, completed to the class's
    shape away from the robot, reaches into the partition. Seen from the partition's other side, the partition's face
    returns a few centimetres in front of that footprint but well in front of every point the LIDAR ever saw of the
    flowers: hidden, not a clear miss (``clear_view_own_points``); measured from the footprint alone, every frame
    there is a miss."""
    from synthetic_scene import Box, Cylinder, detection, detections, raycast

    from app.ocslam.config import ConsciousnessConfig
    from app.ocslam.consciousness import Consciousness

    cam = default_camera()
    partition = Box(2.045, 0.0, 0.03, 3.0, 0.0, 0.0, 2.0)  # its faces at x = 2.03 and 2.06
    flowers = Cylinder(2.18, 0.0, 0.12, 0.0, 0.6)
    cfg = ConsciousnessConfig()
    cfg.clear_view_own_points = own_points
    c = Consciousness(cfg, cam)
    for i in range(6):  # boxed from its open side, 1.3–1.1 m away
        T = Pose2(3.5 - 0.04 * i, 0.02 * i, math.pi)
        c.update(detections([detection("flowers", flowers, T, cam, 0.9)], cam), raycast([partition, flowers], T, cam), T,
                 stamp=0.2 * i)
    (t,) = c._tracks
    fp = t.footprint
    assert fp is not None and fp.center[0] - 0.5 * fp.size_x < 2.03 + 0.1  # within the occlusion margin of its face
    for i in range(5):  # from the partition's other side, no box (the camera sees the partition)
        T = Pose2(0.9 + 0.04 * i, 0.0, 0.0)
        c.update(detections([], cam), raycast([partition, flowers], T, cam), T, stamp=2.0 + 0.2 * i)
    assert (t.misses == 0) if own_points else (t.misses == 5)
