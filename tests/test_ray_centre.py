"""Where the bisector rays cross (issue 9): the boxes of one object seen from several directions fix its
centre; LIDAR points beyond the object's reach of that centre belong to something else.

Known answers of :func:`app.ocslam.ray_centre.ray_centre`, the footprint's choice of points, and a
scenario: a round pedestal table with stools pushed in on three sides, seen only from the open side,
so that the stools stand inside the table's box in every view (the negative evidence of the box's
outside cannot separate them); the rays still cross at the pedestal.
"""

from __future__ import annotations

import math

import numpy as np
from synthetic_scene import Cylinder
from test_fusion_scenarios import arc, found, make, run

from app.ocslam.classes import prior
from app.ocslam.config import ConsciousnessConfig
from app.ocslam.evidence import ObjectEvidence
from app.ocslam.footprint_estimate import estimate_footprint
from app.ocslam.ray_centre import in_front_of_surface, ray_centre, ray_normal_equations


def _rays_at(ev: ObjectEvidence, target: np.ndarray, origins: np.ndarray, app: float, jitter: float = 0.0) -> None:
    rng = np.random.default_rng(1)
    for o in origins:
        d = target - o + rng.normal(0.0, jitter, 2)
        ev.add_ray(o, d, 1.0, apparent_width=app)


def _arc_origins(centre: np.ndarray, r: float, a0: float, a1: float, n: int) -> np.ndarray:
    a = np.linspace(a0, a1, n)
    return centre[None, :] + r * np.stack([np.cos(a), np.sin(a)], axis=1)


def test_ray_centre_known_answer():
    ev = ObjectEvidence()
    c = np.array([1.0, 2.0])
    _rays_at(ev, c, _arc_origins(c, 2.0, -2.0, -1.0, 6), 0.5)
    got = ray_centre(ev)
    assert got is not None
    np.testing.assert_allclose(got[0], c, atol=1e-9)
    # exact rays: the residual floor (2 cm) over the square root of the smallest eigenvalue of Σ n nᵀ
    d = c[None, :] - _arc_origins(c, 2.0, -2.0, -1.0, 6)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    n = np.stack([-d[:, 1], d[:, 0]], axis=1)
    assert math.isclose(got[1], 0.02 / math.sqrt(np.linalg.eigvalsh(n.T @ n)[0]), rel_tol=1e-9)


def test_ray_centre_needs_four_rays_from_more_than_one_direction():
    ev = ObjectEvidence()
    c = np.array([0.0, 0.0])
    _rays_at(ev, c, _arc_origins(c, 2.0, 0.0, 1.0, 3), 0.5)
    assert ray_centre(ev) is None  # three rays
    par = ObjectEvidence()
    for y in (0.0, 0.0, 0.0, 0.0):
        par.add_ray(np.array([-2.0, y]), np.array([1.0, 0.0]), 1.0)
    assert ray_centre(par) is None  # one direction: nothing fixed along it
    cut = ObjectEvidence()
    for o in _arc_origins(c, 2.0, 0.0, 1.0, 6):
        cut.add_ray(o, c - o, 0.0)  # boxes cut by the image border place no centre
    assert ray_centre(cut) is None


def test_rays_of_two_objects_do_not_decide():
    """A track whose boxes were two neighbours' (chairs around a table) has rays that disagree: their
    90th-percentile residual makes σ large, and the footprint is the points' as before."""
    ev = ObjectEvidence()
    a, b = np.array([0.0, 0.0]), np.array([0.9, 0.0])
    _rays_at(ev, a, _arc_origins(a, 2.0, -2.4, -1.6, 6), 0.45)
    _rays_at(ev, b, _arc_origins(b, 2.0, -1.2, -0.4, 6), 0.45)
    rc = ray_centre(ev)
    assert rc is not None and rc[1] > ConsciousnessConfig().ray_centre_sigma_m


def test_lines_that_cross_behind_the_cameras_do_not_place_a_centre():
    """A track that took two tables' boxes while the robot drove a straight stretch: the bisectors' lines from one
    short stretch at two objects ahead cross near the path, behind some of the cameras; a bisector is a half-line,
    so they place nothing. The same rays at one object still cross ahead of every camera."""
    origins = np.stack([np.linspace(0.0, 0.8, 8), np.zeros(8)], axis=1)
    two = ObjectEvidence()
    for k, o in enumerate(origins):
        target = np.array([2.6, 0.9]) if k % 2 else np.array([4.0, -0.1])
        two.add_ray(o, target - o, 1.0, apparent_width=1.0)
    _n, _off, H, g = ray_normal_equations(two, two.ray_weight > 0)
    x = np.linalg.solve(H, g)
    ahead = (x[None, :] - origins) @ np.array([1.0, 0.0])
    assert ahead.min() < 0.1  # the lines do cross behind a camera: the case is not vacuous
    assert ray_centre(two) is None
    one = ObjectEvidence()
    _rays_at(one, np.array([2.6, 0.9]), _arc_origins(np.array([2.6, 0.9]), 2.0, -2.8, -2.2, 8), 1.0)
    got = ray_centre(one)
    assert got is not None and np.allclose(got[0], [2.6, 0.9], atol=1e-6)


def _table_with_stool(sigma: float):
    rng = np.random.default_rng(3)
    pedestal = np.array([3.0, 0.0]) + rng.normal(0.0, 0.02, (12, 2))
    stool = np.array([3.0, 0.75]) + rng.uniform(-0.15, 0.15, (16, 2))
    ev = ObjectEvidence()
    ev.add_points(np.vstack([pedestal, stool]))
    ev.ray_centre_sigma = sigma
    _rays_at(ev, np.array([3.0, 0.0]), _arc_origins(np.array([3.0, 0.0]), 2.0, -2.6, -0.6, 10), 1.0, jitter=0.01)
    return ev


def test_points_beyond_the_reach_of_the_ray_centre_do_not_shape_the_object():
    pc = prior("table")
    off = estimate_footprint(_table_with_stool(0.0), pc)
    on = estimate_footprint(_table_with_stool(0.1), pc)
    assert off is not None and on is not None
    assert math.hypot(off.center[0] - 3.0, off.center[1]) > 0.25  # the stool pulled it
    assert math.hypot(on.center[0] - 3.0, on.center[1]) < 0.05


def test_an_object_whose_points_are_all_someone_elses_stands_where_its_rays_cross():
    """A shelf the LIDAR sees through, a box beside it: every point is the box's."""
    pc = prior("shelf")
    ev = ObjectEvidence()
    ev.add_points(np.array([1.7, 4.0]) + np.random.default_rng(0).uniform(-0.15, 0.15, (20, 2)))
    ev.ray_centre_sigma = 0.1
    _rays_at(ev, np.array([0.6, 4.0]), _arc_origins(np.array([0.6, 4.0]), 2.5, -2.2, -1.0, 8), 0.9)
    fp = estimate_footprint(ev, pc)
    assert fp is not None
    np.testing.assert_allclose(fp.center, [0.6, 4.0], atol=0.02)
    ev.ray_centre_sigma = 0.0
    assert math.hypot(*(estimate_footprint(ev, pc).center - np.array([0.6, 4.0]))) > 0.5  # held by the box's points


def test_a_round_table_with_stools_pushed_in_seen_from_its_open_side():
    """Stools N, E and W of a pedestal table, the robot on an arc south of it: every view has the stools
    inside the table's box. Without the ray centre the table is pulled towards the stools."""
    pedestal, top = Cylinder(3.0, 0.0, 0.05, 0.0, 0.72), Cylinder(3.0, 0.0, 0.5, 0.70, 0.74)
    stools = []
    for sx, sy in ((3.0, 0.67), (3.67, 0.0), (2.33, 0.0)):
        stools += [Cylinder(sx + 0.15 * math.cos(a), sy + 0.15 * math.sin(a), 0.015, 0.0, 0.45) for a in (0.79, 2.36, -0.79, -2.36)]
    poses = arc(30, 3.0, 0.0, 2.0, -math.pi / 2 - 0.6, -math.pi / 2 + 0.6)
    errors = {}
    for sigma in (0.0, ConsciousnessConfig().ray_centre_sigma_m):
        c = make(ray_centre_sigma_m=sigma, central_support=False)  # the rays alone (central_support: test_fusion_scenarios)
        run(c, [pedestal] + stools, [("table", [pedestal, top])], poses)
        tables = found(c, "table")
        assert len(tables) == 1
        errors[sigma] = math.hypot(tables[0].pose.x - 3.0, tables[0].pose.y)
    assert errors[ConsciousnessConfig().ray_centre_sigma_m] < 0.1
    assert errors[0.0] > errors[ConsciousnessConfig().ray_centre_sigma_m] + 0.1


def test_rays_crossing_in_front_of_the_seen_surface_do_not_place_the_centre():
    """An armchair at the back of a bay (one_side_bays): its front face is seen square on from the hall, then from
    45° into the bay, where the stub hides part of it and the boxes' bisectors pass off its centre. The rays cross
    0.1 m in front of the face, on the cameras' side of what the LIDAR saw: no centre of this object. A stray point
    behind (once hit) would otherwise let the crossing fix the centre there."""
    pc = prior("chair")

    def armchair(behind_surface: bool) -> ObjectEvidence:
        ev = ObjectEvidence()
        face = np.stack([np.linspace(0.9, 2.0, 23), np.full(23, 1.84)], axis=1)
        for _ in range(10):
            ev.add_points(face)
        ev.add_points(np.array([[0.9, 2.74]]))  # a stray return, once
        ev.ray_centre_sigma = 0.05
        ev.ray_centre_behind_surface = behind_surface
        crossing = np.array([1.25, 1.74])
        _rays_at(ev, crossing, np.array([[0.4 + 0.03 * k, -0.2 + 0.1 * k] for k in range(6)]), 1.05)
        _rays_at(ev, crossing, np.array([[0.42 + 0.01 * k, 1.11 + 0.005 * k] for k in range(4)]), 0.5)
        return ev

    ev = armchair(True)
    use = ev.ray_weight > 0
    assert in_front_of_surface(ev.ray_origin[use], ev.ray_dir[use], np.array([1.25, 1.74]), ev.points)
    assert not in_front_of_surface(ev.ray_origin[use], ev.ray_dir[use], np.array([1.45, 2.3]), ev.points)
    with_rule, without = estimate_footprint(armchair(True), pc), estimate_footprint(armchair(False), pc)
    assert with_rule is not None and without is not None
    assert without.center[1] < 1.84  # the crossing: in front of its own face
    assert with_rule.center[1] > 1.84 + 0.2  # behind the face, by about half the armchair's depth
