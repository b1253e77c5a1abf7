"""Projection of detection boxes onto the LIDAR plane: improved geometry and the seed's formulas."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.ocslam.camera import CameraModel, ground_plane_point, transform_matrix
from app.ocslam.messages import CLASS_INDEX, CameraInfo, Detection, Detections
from app.ocslam.point_ownership import assign_points, contest_by_range, range_deviation
from app.ocslam.projection import area_from_box, bounding_areas, camera_bound
from app.ocslam.seed_projection import (
    SEED_FY,
    seed_assign_points,
    seed_bounding_areas,
    seed_camera_angles,
    seed_camera_projection,
    seed_project_points,
    seed_projection,
    seed_scan_points,
)

INFO = CameraInfo.from_fov(640, 480, 1.04)
CAM = CameraModel.from_mount(INFO, camera_xyz=(0.0, 0.0, 0.19), scan_xyz=(-0.032, 0.0, 0.173))


def test_projection_matrix_maps_a_known_point():
    # a point 2 m ahead, 0.5 m to the left, 1 m high (base frame)
    p = np.array([[2.0, 0.5, 1.0]])
    uv, depth = CAM.project(p)
    fx, cx, cy = INFO.fx, INFO.cx, INFO.cy
    # optical: x right = -y_base, y down = -(z - 0.19), z forward = x_base
    assert depth[0] == pytest.approx(2.0)
    assert uv[0, 0] == pytest.approx(cx + fx * (-0.5) / 2.0)
    assert uv[0, 1] == pytest.approx(cy + fx * (-(1.0 - 0.19)) / 2.0)
    P = CAM.P
    assert P.shape == (3, 4)


@pytest.mark.parametrize("dist", [1.0, 1.5, 2.0, 3.0])
@pytest.mark.parametrize("lateral", [-0.6, 0.0, 0.4])
def test_ground_plane_point_inverts_the_projection(dist, lateral):
    uv, _ = CAM.project(np.array([[dist, lateral, 0.0]]))
    xy = ground_plane_point(uv[0, 0], uv[0, 1], CAM)
    assert xy is not None
    assert xy == pytest.approx((dist, lateral), abs=1e-9)


@pytest.mark.parametrize("dist", [1.0, 2.0, 3.0])
def test_ground_plane_range_within_5_percent_with_a_pixel_of_error(dist):
    uv, _ = CAM.project(np.array([[dist, 0.0, 0.0]]))
    for dv in (-1.0, 1.0):
        x, _y = ground_plane_point(uv[0, 0], np.round(uv[0, 1]) + dv, CAM)
        assert abs(x - dist) / dist < 0.05 + 0.02 * dist  # 1 px at 3 m is ~5.6 %, rounding adds < 0.5 px
        x, _y = ground_plane_point(uv[0, 0], uv[0, 1] + 0.5 * dv, CAM)
        assert abs(x - dist) / dist < 0.05


def test_rays_above_the_horizon_do_not_hit_the_floor():
    assert ground_plane_point(320.0, INFO.cy - 1.0, CAM) is None
    assert ground_plane_point(320.0, INFO.cy, CAM) is None


def test_known_box_projects_to_known_wedge():
    # a box spanning columns 220..420, bottom at row 320 (80 px below the centre row)
    det = Detection(220.0, 150.0, 420.0, 320.0, CLASS_INDEX["chair"], 0.9)
    area = area_from_box(det, CAM, max_range_m=3.5, bottom_margin_px=0.0)
    assert area is not None
    fx, cx, cy = INFO.fx, INFO.cx, INFO.cy
    # level camera: the column u's half-line has bearing atan((cx - u)/fx) about the apex (camera foot)
    assert area.bearing_left == pytest.approx(np.arctan((cx - 220.0) / fx), abs=1e-9)
    assert area.bearing_right == pytest.approx(np.arctan((cx - 420.0) / fx), abs=1e-9)
    assert area.bearing_center == pytest.approx(0.0, abs=1e-9)
    assert area.apex == pytest.approx([0.032, 0.0])  # the camera foot in base_scan
    # bottom edge: the floor at depth h·fy/(v − cy)
    assert area.near_range_m == pytest.approx(0.19 * INFO.fy / (320.0 - cy), rel=1e-9)
    poly = area.polygon
    apex = area.apex
    inside = apex + np.array([[1.5, 0.0], [2.5, 0.3], [3.0, -0.4]])
    outside = apex + np.array([[0.5, 0.0], [2.0, 1.0], [3.6, 0.0], [2.0, -0.8]])
    assert all(poly.contains(__import__("shapely").Point(p)) for p in inside)
    assert not any(poly.contains(__import__("shapely").Point(p)) for p in outside)
    assert area.bisector.shape == (2, 2)
    assert not any(area.truncated.values())


def test_truncated_box_has_no_near_edge():
    det = Detection(0.0, 100.0, 200.0, 480.0, CLASS_INDEX["chair"], 0.9)
    area = area_from_box(det, CAM, 3.5)
    assert area.truncated["left"] and area.truncated["bottom"]
    assert not area.bottom_reliable
    assert area.near_range_lo == 0.0


def test_camera_bound_spans_the_field_of_view():
    poly = camera_bound(CAM, 3.5)
    apex = CAM.apex_scan
    for b in (-0.5, 0.0, 0.5):
        p = apex + 2.0 * np.array([np.cos(b), np.sin(b)])
        assert poly.contains(__import__("shapely").Point(p))
    for b in (-0.56, 0.56, np.pi):
        p = apex + 2.0 * np.array([np.cos(b), np.sin(b)])
        assert not poly.contains(__import__("shapely").Point(p))


def test_boxes_of_another_resolution_are_rescaled():
    det = Detection(110.0, 75.0, 210.0, 160.0, 0, 0.9)  # at 320x240
    a_half = bounding_areas(Detections(0.0, 320, 240, (det,)), CAM, 3.5)[0]
    full = Detection(220.0, 150.0, 420.0, 320.0, 0, 0.9)
    a_full = bounding_areas(Detections(0.0, 640, 480, (full,)), CAM, 3.5)[0]
    assert a_half.bearing_left == pytest.approx(a_full.bearing_left)
    assert a_half.near_range_m == pytest.approx(a_full.near_range_m)
    assert a_half.detection is det


def test_degenerate_boxes_are_skipped():
    dets = Detections(0.0, 640, 480, (Detection(10, 10, 10.5, 20, 0, 0.9), Detection(np.nan, 0, 5, 5, 0, 0.9)))
    assert bounding_areas(dets, CAM, 3.5) == []


def test_exclusive_assignment_gives_a_point_to_the_area_its_range_fits():
    near_box = Detection(280.0, 200.0, 360.0, 0.0 + 240 + 0.19 * INFO.fy / 1.0, 0, 0.9)  # bottom: floor at 1 m
    far_box = Detection(200.0, 100.0, 440.0, 240 + 0.19 * INFO.fy / 2.5, 10, 0.9)  # bottom: floor at 2.5 m
    areas = bounding_areas([near_box, far_box], CAM, 3.5)
    apex = CAM.apex_scan
    pts = apex + np.array([[1.05, 0.0], [2.55, 0.02], [2.6, 0.5]])
    shared = assign_points(pts, areas, exclusive=False)
    assert shared[1].tolist() == [True, True]  # both wedges hold the far point
    excl = assign_points(pts, areas, exclusive=True)
    assert excl.sum(axis=1).tolist() == [1, 1, 1]
    assert excl[0].tolist() == [True, False]
    assert excl[1].tolist() == [False, True]
    assert excl[2].tolist() == [False, True]


def test_a_shared_point_goes_to_the_boxes_whose_bottom_range_explains_it():
    """A table's leg 1.95 m away lies in the wedge of the table's box (bottom edge: floor at 1.9 m) and of a
    chair's box behind it (floor at 2.5 m; its wedge starts 25 % nearer): the chair's box loses it, the
    table's box loses a point at the chair's range, a point halfway stays with both within the slack
    (neither box explains it much better), and a box cut at the bottom (no range) never loses a point."""
    table = Detection(200.0, 150.0, 440.0, 240 + 0.19 * INFO.fy / 1.9, CLASS_INDEX["table"], 0.9)
    chair = Detection(280.0, 100.0, 360.0, 240 + 0.19 * INFO.fy / 2.5, CLASS_INDEX["chair"], 0.9)
    cut = Detection(250.0, 100.0, 390.0, 480.0, CLASS_INDEX["person"], 0.9)  # bottom at the image border
    areas = bounding_areas([table, chair, cut], CAM, 3.5, bottom_margin_px=0.0)
    assert [a.bottom_reliable for a in areas] == [True, True, False]
    apex = CAM.apex_scan
    pts = apex + np.array([[1.95, 0.0], [2.5, 0.01], [2.2, 0.0]])
    dev = np.column_stack([range_deviation(pts, a) for a in areas])
    assert dev[0, 0] == pytest.approx(0.05 / 1.95, abs=1e-3) and dev[0, 1] == pytest.approx(0.55 / 1.95, abs=1e-3)
    assert dev[1, 1] == pytest.approx(0.0, abs=1e-3) and dev[1, 0] == pytest.approx(0.6 / 2.5, abs=1e-3)
    assert np.isnan(dev[:, 2]).all()
    member = assign_points(pts, areas, exclusive=False)
    assert member.all()  # every wedge holds every point
    out = contest_by_range(pts, areas, member, slack=0.1)
    assert out[0].tolist() == [True, False, True]  # the leg: the table's (and the cut box keeps it)
    assert out[1].tolist() == [False, True, True]  # at the chair's range: the chair's
    # 2.2 m: 0.3 m beyond the table's range and 0.3 m before the chair's: neither loses it
    assert out[2].tolist() == [True, True, True]
    assert contest_by_range(pts, areas, member, slack=0.3)[0].tolist() == [True, True, True]  # within a wide slack
    assert member.all()  # the input is not modified


@settings(max_examples=60, deadline=None)
@given(
    u=st.floats(0.0, 640.0),
    v=st.floats(260.0, 480.0),
    pitch=st.floats(-0.2, 0.2),
    z=st.floats(0.1, 0.4),
)
def test_pixel_ray_round_trip(u, v, pitch, z):
    cam = CameraModel.from_mount(INFO, camera_xyz=(0.05, 0.01, z), camera_rpy=(0.0, pitch, 0.0))
    p, ok = cam.rays_to_plane(np.array([[u, v]]), 0.0)
    if not ok[0]:
        return
    uv, depth = cam.project(p)
    assert depth[0] > 0
    assert uv[0] == pytest.approx([u, v], abs=1e-6)


@settings(max_examples=40, deadline=None)
@given(pitch=st.floats(-0.25, 0.25), u=st.floats(0.0, 640.0), v=st.floats(0.0, 480.0))
def test_column_half_line_holds_every_pixel_of_the_column(pitch, u, v):
    """Every pixel of column u that sees the LIDAR plane sees it on the column's half-line."""
    cam = CameraModel.from_mount(INFO, camera_xyz=(0.0, 0.0, 0.19), camera_rpy=(0.0, pitch, 0.0))
    p, ok = cam.rays_to_plane(np.array([[u, v]]), cam.lidar_height)
    if not ok[0]:
        return
    d = cam.column_directions_base(np.array([u]))[0]
    rel = p[0, :2] - cam.apex_base
    cross = rel[0] * d[1] - rel[1] * d[0]
    assert abs(cross) < 1e-6 * max(1.0, np.linalg.norm(rel))
    assert rel @ d >= -1e-9


def test_column_bearings_decrease_left_to_right():
    b = CAM.column_bearings_scan(np.linspace(0, 640, 33))
    assert np.all(np.diff(b) < 0)
    assert b[0] == pytest.approx(0.52, abs=1e-6) and b[-1] == pytest.approx(-0.52, abs=1e-6)


def test_rejects_malformed_extrinsics():
    with pytest.raises(ValueError):
        CameraModel(INFO, np.eye(3), np.eye(4))
    with pytest.raises(ValueError):
        CameraModel(INFO, np.full((4, 4), np.nan), np.eye(4))
    T = transform_matrix((0, 0, 0.19), (0, 0, 0))
    assert T.shape == (4, 4)


# -- seed-faithful geometry (spec §1.2–1.4) ---------------------------------------------------


def test_seed_camera_bound_constants():
    a_min, a_max = seed_camera_angles()
    assert a_min == pytest.approx(-0.5539, abs=1e-4)
    assert a_max == pytest.approx(0.5185, abs=1e-4)
    cam = seed_camera_projection()
    assert cam.near_midpoint == pytest.approx([0.0887, -0.0021], abs=1e-4)
    assert cam.vertices[2, 0] == pytest.approx(0.04 * SEED_FY)  # the 22.64 m clamp
    assert cam.vertices[2, 0] == pytest.approx(22.64, abs=0.01)


@pytest.mark.parametrize("row", [300.0, 350.0, 400.0, 470.0])
def test_seed_row_to_distance(row):
    """After the flip, row r maps to X = 0.04·566.11/(r − 249.64)."""
    proj = seed_projection(100.0, 50.0, 200.0, row)
    assert proj.vertices[0, 0] == pytest.approx(0.04 * 566.112 / (row - 249.6415), rel=1e-4)
    # the top of the box (above the horizon) is clamped at 22.64 m
    assert proj.vertices[3, 0] == pytest.approx(22.64, abs=0.01)


def test_seed_widens_the_right_edge_only():
    p = seed_projection(100.0, 50.0, 200.0, 400.0)
    u1 = (100.0 - 322.4309) / 565.1448
    u2 = (1.05 * 200.0 - 322.4309) / 565.1448
    X = p.vertices[0, 0]
    assert p.vertices[0, 1] == pytest.approx(-u1 * X)
    assert p.vertices[1, 1] == pytest.approx(-u2 * X)
    pts = seed_project_points(np.array([[0.0, 0.0]]))
    assert pts[0, 0] == pytest.approx(0.0887, abs=1e-4)


def test_seed_points_may_belong_to_several_areas_and_containment_is_strict():
    a = seed_projection(100.0, 50.0, 300.0, 400.0)
    b = seed_projection(200.0, 50.0, 400.0, 400.0)
    pts = np.array([[2.0, 0.2], [2.0, 0.6]])
    m = seed_assign_points(pts, [a, b])
    assert m[0].all()  # in both
    assert m[1].tolist() == [True, False]
    vertex = a.vertices[0][None, :]
    assert not seed_assign_points(vertex, [a]).any()  # on the boundary: not strictly inside


def test_seed_areas_are_in_the_640x480_camera_pixels_whatever_the_render_size():
    # the same box seen in a 320x240 render and in the original's 640x480 image: the same area
    half = Detections(0.0, 320, 240, (Detection(110.0, 75.0, 210.0, 160.0, 0, 0.9),))
    full = Detections(0.0, 640, 480, (Detection(220.0, 150.0, 420.0, 320.0, 0, 0.9),))
    (a,) = seed_bounding_areas(half)
    (b,) = seed_bounding_areas(full)
    np.testing.assert_allclose(a.vertices, b.vertices)
    np.testing.assert_allclose(b.vertices, seed_projection(220.0, 150.0, 420.0, 320.0).vertices)
    assert a.detection is half.boxes[0]


def test_seed_scan_points_use_strict_camera_angles_and_skip_inf():
    n = 360
    angles = -np.pi + 2 * np.pi * np.arange(n) / n
    r = np.full(n, 2.0)
    r[180] = np.inf  # straight ahead
    pts = seed_scan_points(r, -np.pi, 2 * np.pi / n)
    th = np.arctan2(pts[:, 1], pts[:, 0])
    a_min, a_max = seed_camera_angles()
    assert np.all(th > a_min) and np.all(th < a_max)
    expected = np.sum((angles > a_min) & (angles < a_max)) - 1
    assert len(pts) == expected


_box = st.tuples(st.floats(-50, 700), st.floats(-50, 530), st.floats(-50, 700), st.floats(-50, 530), st.floats(0.1, 1.0))


@settings(max_examples=50, deadline=None)
@given(boxes=st.lists(_box, min_size=0, max_size=8), allow_nan=st.booleans())
def test_a_frame_of_boxes_gives_the_areas_of_its_boxes_one_by_one(boxes, allow_nan):
    # bounding_areas computes a frame's boxes together: each area is the one its box gives alone
    dets = [Detection(x1, y1, x2, y2, 0, c) for x1, y1, x2, y2, c in boxes]
    if allow_nan and dets:
        dets.insert(len(dets) // 2, Detection(np.nan, 0, 5, 5, 0, 0.9))
    together = bounding_areas(Detections(0.0, 640, 480, tuple(dets)), CAM, 3.5)
    alone = [a for a in (area_from_box(d, CAM, 3.5) for d in dets) if a is not None]
    assert len(together) == len(alone)
    for a, b in zip(together, alone):
        assert a.detection is b.detection
        assert a.truncated == b.truncated
        np.testing.assert_allclose([a.bearing_left, a.bearing_right, a.bearing_center, a.near_range_lo, a.near_range_hi],
                                   [b.bearing_left, b.bearing_right, b.bearing_center, b.near_range_lo, b.near_range_hi],
                                   rtol=0, atol=1e-12)
        np.testing.assert_array_equal(a.box_px, b.box_px)
        assert a.polygon.equals_exact(b.polygon, 1e-9)


def test_wedge_membership_by_bearing_and_range_equals_the_polygons() -> None:
    """assign_points tests simple wedges by bearing and range about the apex, the points within 1e-8 of
    an outline on the polygon: the same as shapely's strict containment, on the outline too."""
    import shapely

    rng = np.random.default_rng(7)
    for _ in range(40):
        cam = CameraModel.from_mount(INFO, camera_xyz=(float(rng.uniform(-0.1, 0.1)), 0.0, float(rng.uniform(0.1, 0.5))),
                                     camera_rpy=(0.0, float(rng.uniform(-0.2, 0.2)), float(rng.uniform(-0.3, 0.3))),
                                     scan_xyz=(-0.03, 0.01, 0.17), scan_yaw=float(rng.uniform(-0.3, 0.3)))
        dets = []
        for _k in range(int(rng.integers(1, 5))):
            x1, x2 = sorted(rng.uniform(-20, 660, 2))
            y1, y2 = sorted(rng.uniform(-20, 500, 2))
            dets.append(Detection(x1, y1, x2, y2, 0, 0.9))
        areas = bounding_areas(dets, cam, float(rng.uniform(2, 8)), near_tolerance=float(rng.choice([0.25, 2.0])))
        pts = [rng.uniform(-8, 8, (200, 2)), np.array([[np.nan, 0.0], [np.inf, 1.0]])]
        for a in areas:
            ring = np.asarray(a.polygon.exterior.coords)
            f = rng.uniform(0, 1, (len(ring) - 1, 1))
            edges = ring[:-1] * f + ring[1:] * (1 - f)
            pts += [ring, ring + rng.normal(size=ring.shape) * 1e-12, edges, edges + rng.normal(size=edges.shape) * 1e-9,
                    a.apex[None, :]]
        p = np.vstack(pts)
        want = np.column_stack([shapely.contains_xy(a.polygon, p[:, 0], p[:, 1]) & np.isfinite(p).all(axis=1) for a in areas])
        np.testing.assert_array_equal(assign_points(p, areas, exclusive=False), want.reshape(len(p), len(areas)))
