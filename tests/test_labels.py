"""Labels from segmentation masks: tight visible boxes, visibility filtering, off-centre silhouette windows."""

from __future__ import annotations

import numpy as np
import pybullet as p
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.training.labels import LabelFilter, make_labels, visible_boxes, yolo_lines
from app.training.silhouettes import frustum_matrix, silhouette_window


def test_visible_boxes_are_tight() -> None:
    seg = np.full((20, 30), -1, np.int32)
    seg[2:5, 3:9] = 7
    seg[10:19, 20:30] = 2
    seg[12, 21] = -1  # a hole does not change the box
    boxes = visible_boxes(seg)
    assert boxes == {7: (3, 2, 9, 5, 18), 2: (20, 10, 30, 19, 89)}
    assert visible_boxes(np.full((4, 4), -1)) == {}
    with pytest.raises(ValueError):
        visible_boxes(np.zeros((2, 2, 2)))


@settings(max_examples=50, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_visible_boxes_match_a_direct_computation(seed: int) -> None:
    rng = np.random.default_rng(seed)
    seg = rng.integers(-1, 5, size=(rng.integers(1, 25), rng.integers(1, 25))).astype(np.int32)
    seg[rng.random(seg.shape) < 0.5] = -1
    boxes = visible_boxes(seg)
    assert set(boxes) == set(int(v) for v in np.unique(seg) if v >= 0)
    for oid, (x1, y1, x2, y2, n) in boxes.items():
        r, c = np.nonzero(seg == oid)
        assert (x1, y1, x2, y2, n) == (c.min(), r.min(), c.max() + 1, r.max() + 1, len(r))


def test_make_labels_filters_by_pixels_fraction_and_size() -> None:
    seg = np.full((100, 100), -1, np.int32)
    seg[10:30, 10:30] = 1  # 400 px, fully visible
    seg[50:60, 50:90] = 2  # 400 px of a 2000 px object: 20 % visible → ignore region
    seg[80:82, 0:40] = 3  # 80 px but only 2 px tall → ignore
    seg[90:95, 90:95] = 4  # 25 px → ignore
    seg[0:5, 60:70] = 9  # not a classified object (wall, distractor): no label at all
    labels = make_labels(seg, {1: 0, 2: 3, 3: 5, 4: 6}, {2: 2000}, LabelFilter(min_pixels=40, min_visible_fraction=0.35, min_box_px=4, reference_width=100))
    by = {lb.object_id: lb for lb in labels}
    assert set(by) == {1, 2, 3, 4}
    assert by[1].keep and by[1].visible_fraction == 1.0
    assert not by[2].keep and by[2].visible_fraction == pytest.approx(0.2)
    assert not by[3].keep and not by[4].keep
    assert yolo_lines(labels, 100, 100) == ["0 0.200000 0.200000 0.200000 0.200000"]
    # A looser fraction threshold keeps the occluded object, with its visible box.
    loose = make_labels(seg, {2: 3}, {2: 2000}, LabelFilter(min_pixels=40, min_visible_fraction=0.1, min_box_px=4, reference_width=100))
    assert loose[0].keep and (loose[0].x1, loose[0].y1, loose[0].x2, loose[0].y2) == (50, 50, 90, 60)
    # Cut by the frame to 40 % of itself: not kept, though 40 % visible passes the visibility test.
    cut = make_labels(seg, {1: 0}, {1: 1000}, LabelFilter(40, 0.35, 4, 100), in_frame_pixels={1: 400})
    assert cut[0].in_frame_fraction == pytest.approx(0.4) and not cut[0].keep
    half = make_labels(seg, {1: 0}, {1: 1000}, LabelFilter(40, 0.35, 4, 100), in_frame_pixels={1: 600})
    assert half[0].keep
    # Thresholds are in pixels of the reference width: the same mask at twice the resolution keeps
    # the same objects.
    big = np.kron(seg, np.ones((2, 2), np.int32))
    f = LabelFilter(min_pixels=40, min_visible_fraction=0.35, min_box_px=4, reference_width=100)
    assert [lb.keep for lb in make_labels(big, {1: 0, 3: 5, 4: 6}, {}, f)] == [True, False, False]


def test_silhouette_window_projects_and_extends() -> None:
    K = np.array([[100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]])
    cube = np.array([[x, y, z] for x in (-0.1, 0.1) for y in (-0.1, 0.1) for z in (1.9, 2.1)])
    u0, v0, u1, v1 = silhouette_window(cube, K, 100, 80, near=0.05)
    assert (u0, v0) == (44, 34) and (u1, v1) == (57, 47)
    # Far to the right: still a window, past the frame edge.
    w = silhouette_window(cube + [1.5, 0, 0], K, 100, 80, near=0.05)
    assert w is not None and w[0] > 100
    # Straddling the camera plane: the whole extended plane; behind: None.
    assert silhouette_window(cube - [0, 0, 2.0], K, 100, 80, near=0.05) == (-100, -80, 200, 160)
    assert silhouette_window(cube - [0, 0, 5.0], K, 100, 80, near=0.05) is None


def test_frustum_matches_pybullet_for_the_full_frame() -> None:
    W, H, fov_v = 64, 48, 60.0
    fy = (H / 2) / np.tan(np.radians(fov_v) / 2)
    K = np.array([[fy, 0, W / 2], [0, fy, H / 2], [0, 0, 1]])
    ref = p.computeProjectionMatrixFOV(fov_v, W / H, 0.05, 20.0)
    np.testing.assert_allclose(frustum_matrix(K, (0, 0, W, H), 0.05, 20.0), ref, rtol=1e-5, atol=1e-6)


def test_window_render_equals_a_crop_of_the_full_render() -> None:
    """Rendering a sub-window of the image plane with frustum_matrix gives the same pixels as the crop."""
    cid = p.connect(p.DIRECT)
    try:
        vs = p.createVisualShape(p.GEOM_BOX, halfExtents=[0.2, 0.3, 0.25], physicsClientId=cid)
        p.createMultiBody(0, -1, vs, basePosition=[2.0, 0.3, 0.2], physicsClientId=cid)
        W, H = 80, 60
        fx = (W / 2) / np.tan(0.52)
        K = np.array([[fx, 0, W / 2], [0, fx, H / 2], [0, 0, 1]])
        view = p.computeViewMatrix([0, 0, 0.2], [1, 0, 0.2], [0, 0, 1])
        full = p.getCameraImage(W, H, view, frustum_matrix(K, (0, 0, W, H), 0.05, 20.0),
                                renderer=p.ER_TINY_RENDERER, physicsClientId=cid)[4]
        full = np.asarray(full).reshape(H, W)
        win = (20, 10, 70, 50)
        part = p.getCameraImage(win[2] - win[0], win[3] - win[1], view, frustum_matrix(K, win, 0.05, 20.0),
                                renderer=p.ER_TINY_RENDERER, physicsClientId=cid)[4]
        part = np.asarray(part).reshape(win[3] - win[1], win[2] - win[0])
        crop = full[win[1]:win[3], win[0]:win[2]]
        assert (crop == 0).sum() > 100
        assert np.mean(part == crop) > 0.99
    finally:
        p.disconnect(cid)


def _sphere_box(c_cam: np.ndarray, r: float, K: np.ndarray) -> tuple[float, float, float, float]:
    """Exact image box of a sphere (centre ``c_cam`` in the optical frame): the tangent planes through
    the camera centre that contain the image's vertical (horizontal) direction."""
    def extent(a: float, z: float, f: float, c: float) -> tuple[float, float]:
        # planes a = m z tangent to the sphere: (a - m z)^2 = r^2 (1 + m^2)
        A, B, C = z * z - r * r, -2 * a * z, a * a - r * r
        d = np.sqrt(B * B - 4 * A * C)
        m1, m2 = (-B - d) / (2 * A), (-B + d) / (2 * A)
        return c + f * min(m1, m2), c + f * max(m1, m2)

    u0, u1 = extent(c_cam[0], c_cam[2], K[0, 0], K[0, 2])
    v0, v1 = extent(c_cam[1], c_cam[2], K[1, 1], K[1, 2])
    return u0, v0, u1, v1


def test_labels_from_a_rendered_scene_match_the_known_objects() -> None:
    from app.config import Config
    from app.ocslam.messages import CLASS_INDEX
    from app.ocslam.se2 import Pose2
    from app.sim_world import SimWorld
    from app.training.silhouettes import SilhouetteRenderer
    from app.world.types import World, WorldObject

    world = World(
        name="tiny",
        objects=[
            WorldObject("ball", "play_ball", 2.0, 0.25),  # fully visible
            WorldObject("duck", "rubber_duck", 3.2, 0.57),  # behind the ball's left edge: partly hidden
            WorldObject("ball", "play_ball", 2.0, -1.15),  # at the right edge: half out of the frame
            WorldObject("gnome", "gnome", -2.0, 0.0),  # behind the camera
        ],
    )
    W, H = 320, 240
    with SimWorld(world, Config()) as sim, SilhouetteRenderer(world) as sil:
        frame = sim.render_view(Pose2(0.0, 0.0, 0.0), width=W, height=H, camera_z=0.11, segmentation=True)
        class_of = {i: CLASS_INDEX[o.label] for i, o in enumerate(world.objects)}
        vis = visible_boxes(frame.segmentation)
        sils = sil.silhouettes(frame.T_world_camera, frame.info.K, W, H, list(vis))
        full = {k: v[0] for k, v in sils.items()}
        inside = {k: v[1] for k, v in sils.items()}
        labels = {
            lb.object_id: lb
            for lb in make_labels(frame.segmentation, class_of, full, LabelFilter(40, 0.35, 4, reference_width=W), inside)
        }
    assert set(labels) == {0, 1, 2}  # the gnome behind the camera is not seen
    # The fully visible ball: its exact projected sphere box, visible fraction 1.
    c_world = np.array([2.0, 0.25, 0.11, 1.0])
    c_cam = (np.linalg.inv(frame.T_world_camera) @ c_world)[:3]
    u0, v0, u1, v1 = _sphere_box(c_cam, 0.1115, frame.info.K)
    ball = labels[0]
    assert ball.keep and ball.class_id == CLASS_INDEX["ball"]
    np.testing.assert_allclose([ball.x1, ball.y1, ball.x2, ball.y2], [u0, v0, u1, v1], atol=1.5)
    assert ball.visible_fraction == pytest.approx(1.0, abs=0.02)
    # The duck behind it is partly occluded; the right ball is truncated at the frame edge.
    assert 0.0 < labels[1].visible_fraction < 0.9
    right = labels[2]
    assert right.x2 == W and 0.2 < right.visible_fraction < 0.8
    # Nothing hides it: its in-frame silhouette is what is visible, and less than half is in the frame.
    assert right.in_frame_pixels == pytest.approx(right.visible_pixels, rel=0.03)
    assert not right.keep and labels[0].in_frame_fraction == 1.0


def test_tall_objects_cut_by_the_top_edge_count_as_visible() -> None:
    """The low camera cuts a person at 1 m at the top edge: still fully 'visible'; cut at the side, not."""
    from app.config import Config
    from app.ocslam.se2 import Pose2
    from app.sim_world import SimWorld
    from app.training.silhouettes import SilhouetteRenderer
    from app.world.types import World, WorldObject

    world = World(name="person", objects=[WorldObject("person", "person", 1.0, 0.0, yaw=3.14)])
    W, H = 160, 120
    with SimWorld(world, Config()) as sim, SilhouetteRenderer(world) as sil:
        frame = sim.render_view(Pose2(0.0, 0.0, 0.0), width=W, height=H, segmentation=True)
        x1, y1, x2, y2, n = visible_boxes(frame.segmentation)[0]
        assert y1 == 0 and 0 < x1 < x2 < W  # cut at the top only
        top_free = sil.counts(frame.T_world_camera, frame.info.K, W, H, [0])[0]
        top_counted = sil.counts(frame.T_world_camera, frame.info.K, W, H, [0], margin_top=1.0)[0]
        assert n / top_free == pytest.approx(1.0, abs=0.03)
        assert n / top_counted < 0.7
        side = sim.render_view(Pose2(0.0, 0.0, 0.45), width=W, height=H, segmentation=True)  # person at the right edge
        vb = visible_boxes(side.segmentation)[0]
        assert vb[2] == W and vb[4] / sil.counts(side.T_world_camera, side.info.K, W, H, [0])[0] < 0.8


def test_silhouettes_shared_model_clients_across_worlds() -> None:
    """One models' client serves every world: an object moved and turned, seen from a camera moved and
    turned with it, has the same silhouette; two worlds share the client; closing a renderer leaves a
    shared client open; another model in the client does not change a silhouette."""
    from app.training.silhouettes import ModelClient, SilhouetteRenderer
    from app.world.types import World, WorldObject

    K = np.array([[160.0, 0.0, 160.0], [0.0, 160.0, 120.0], [0.0, 0.0, 1.0]])

    def camera(x: float, y: float, yaw: float) -> np.ndarray:
        """T_world_camera (optical: z forward, x right, y down) at 0.11 m looking along ``yaw``."""
        c, s = np.cos(yaw), np.sin(yaw)
        T = np.eye(4)
        T[:3, :3] = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ np.array(
            [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
        T[:3, 3] = [x, y, 0.11]
        return T

    a = World(name="a", objects=[WorldObject("chair", "dining_chair", 2.0, 0.3, yaw=0.4)])
    yaw = 1.9  # the same scene turned by `yaw` about the origin and shifted
    c, s = np.cos(yaw), np.sin(yaw)
    shift = np.array([-3.0, 5.0])
    x, y = np.array([[c, -s], [s, c]]) @ [2.0, 0.3] + shift
    b = World(name="b", objects=[WorldObject("duck", "rubber_duck", 0.0, 9.0), WorldObject("chair", "dining_chair", x, y, yaw=0.4 + yaw)])
    shared = ModelClient()
    try:
        with SilhouetteRenderer(a, clients=shared) as ra, SilhouetteRenderer(b, clients=shared) as rb:
            got_a = ra.silhouettes(camera(0.0, 0.0, 0.1), K, 320, 240, [0])[0]
            got_b = rb.silhouettes(camera(shift[0], shift[1], 0.1 + yaw), K, 320, 240, [1])[1]
        assert got_a[0] > 1000 and got_a[1] > 1000
        assert got_b[0] == pytest.approx(got_a[0], rel=0.02) and got_b[1] == pytest.approx(got_a[1], rel=0.02)
        assert len(shared) == 1  # the chair served both worlds; the duck was never rendered
        with SilhouetteRenderer(a) as own:  # its own client: the same counts
            assert own.silhouettes(camera(0.0, 0.0, 0.1), K, 320, 240, [0])[0] == got_a
        assert len(shared) == 1
        with SilhouetteRenderer(b, clients=shared) as rb:  # the duck joins the client (at the origin, as the chair)
            duck = rb.silhouettes(camera(-0.6, 9.0, 0.0), K, 320, 240, [0])[0]
            assert len(shared) == 2 and duck[0] > 100
            assert rb.silhouettes(camera(shift[0], shift[1], 0.1 + yaw), K, 320, 240, [1])[1] == got_b  # no duck in it
            assert rb.silhouettes(camera(-0.6, 9.0, 0.0), K, 320, 240, [0])[0] == duck  # nor chair in the duck's
    finally:
        shared.close()


def _box_corners(lo, hi) -> np.ndarray:
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])], dtype=float)


def test_may_be_labelled_known_answers() -> None:
    """The camera at the origin looking along world +x (optical z = world x, x = −y, y = −z)."""
    from app.ocslam.messages import CameraInfo
    from app.training.labels import may_be_labelled

    T = np.eye(4)
    T[:3, :3] = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    T[2, 3] = 0.2
    K = CameraInfo.from_fov(320, 240, 1.04).K

    def may(*boxes, min_pixels=50.0, min_box=6.0) -> bool:
        return may_be_labelled(np.array(boxes).reshape(-1, 8, 3), T, K, 320, 240, 0.05, min_pixels, min_box)

    ahead = _box_corners((2.0, -0.2, 0.0), (2.4, 0.2, 0.5))
    assert may(ahead)
    assert not may(_box_corners((-2.4, -0.2, 0.0), (-2.0, 0.2, 0.5)))  # behind the camera
    assert not may(_box_corners((2.0, 3.0, 0.0), (2.4, 3.4, 0.5)))  # far to the left, outside the field of view
    assert not may(_box_corners((40.0, 0.0, 0.0), (40.02, 0.02, 0.02)))  # a speck: fewer pixels than a label needs
    assert may(_box_corners((40.0, 0.0, 0.0), (40.02, 0.02, 0.02)), min_pixels=0.5, min_box=0.5)
    assert may(_box_corners((-0.5, -0.2, 0.0), (0.5, 0.2, 0.5)))  # across the camera's plane: could fill the view
    assert may(_box_corners((2.0, 3.0, 0.0), (2.4, 3.4, 0.5)), ahead)  # one box that may be labelled is enough
    assert not may_be_labelled(np.zeros((0, 8, 3)), T, K, 320, 240, 0.05, 50.0, 6.0)


def test_views_that_may_not_be_labelled_hold_no_label() -> None:
    """Rendered views of a generated world: every view in which some object covers enough pixels and a large
    enough box to become a label is one that :func:`may_be_labelled` lets through, and some views are not."""
    from app.config import Config
    from app.ocslam.se2 import Pose2
    from app.sim_world import SimWorld
    from app.training.labels import may_be_labelled, object_boxes
    from app.world.generator import random_world

    world = random_world(7, family="rooms")
    W, H = 160, 120
    filt = LabelFilter()
    min_px, min_box = filt.scaled(W)
    boxes = object_boxes(world.objects)
    rng = np.random.default_rng(3)
    xmin, ymin, xmax, ymax = world.bounds()
    maybe = labelled = 0
    with SimWorld(world, Config(), renderer="tiny") as sim:
        n = 0
        while n < 60:
            x, y = rng.uniform(xmin, xmax), rng.uniform(ymin, ymax)
            if not sim.pose_free(x, y):
                continue
            n += 1
            pose, cam_z, pitch = Pose2(x, y, rng.uniform(-np.pi, np.pi)), 0.2 + rng.uniform(-0.05, 0.07), rng.uniform(-0.08, 0.12)
            T = sim.view_camera_pose(pose, camera_z=cam_z, pitch_rad=pitch)
            frame = sim.render_view(pose, width=W, height=H, camera_z=cam_z, pitch_rad=pitch, segmentation=True)
            np.testing.assert_allclose(T, frame.T_world_camera)
            ok = may_be_labelled(boxes, T, frame.info.K, W, H, 0.05, min_px, min_box)
            big = [i for i, (x1, y1, x2, y2, k) in visible_boxes(frame.segmentation).items()
                   if 0 <= i < len(world.objects) and k >= min_px and min(x2 - x1, y2 - y1) >= min_box]
            assert ok or not big, f"view {n}: objects {big} could be labelled but the view was ruled out"
            maybe += ok
            labelled += bool(big)
    assert 0 < maybe < 60 and labelled > 0
