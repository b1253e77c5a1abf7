"""The model catalogue: classes, sizes (spec §5), legs at LIDAR height, pybullet = trimesh geometry."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh
from shapely.geometry import Polygon
from shapely.ops import unary_union

from app.ocslam.messages import CLASS_NAMES
from app.world.models.bodies import build_model_pybullet
from app.world.models.catalogue import MODELS, get_model, models_for_class
from app.world.models.colors import jitter_color, parse_color
from app.world.models.geometry import model_footprint, model_z_range
from app.world.models.meshes import model_parts_trimesh, model_trimesh, world_visual_meshes
from app.world.models.parts import COLLISION_ONLY, MESH_DIR

LIDAR_Z = 0.173


def section_at(name: str, z: float):
    """Union of the model's cross-sections at height z (shapely), from its trimesh parts."""
    polys = []
    for m, _ in model_parts_trimesh(name):
        if not (m.bounds[0, 2] < z < m.bounds[1, 2]):
            continue
        sec = m.section(plane_origin=[0, 0, z], plane_normal=[0, 0, 1])
        if sec is None:
            continue
        planar, T = sec.to_2D()
        for p in planar.polygons_full:
            pts = np.c_[np.asarray(p.exterior.coords), np.zeros(len(p.exterior.coords)), np.ones(len(p.exterior.coords))]
            polys.append(Polygon((T @ pts.T).T[:, :2]))
    return unary_union(polys) if polys else Polygon()


def test_every_class_has_a_model_and_models_have_known_classes():
    for c in CLASS_NAMES:
        assert models_for_class(c), c
    for name, spec in MODELS.items():
        assert spec.label is None or spec.label in CLASS_NAMES
        assert spec.primary in spec.colors, name
        roles = {p.role for p in spec.parts} - {COLLISION_ONLY}
        assert roles <= set(spec.colors), (name, roles - set(spec.colors))
        for c in spec.palette:
            assert all(0.0 <= v <= 1.0 for v in c), name
    with pytest.raises(KeyError, match="unknown model 'unicorn'"):
        get_model("unicorn")


@pytest.mark.parametrize("name", sorted(MODELS))
def test_footprint_is_ccw_convex_and_centred(name):
    fp = model_footprint(name)
    poly = Polygon(fp)
    assert poly.is_valid and poly.exterior.is_ccw and poly.area > 0.005
    assert poly.convex_hull.area == pytest.approx(poly.area, rel=1e-6)
    z0, z1 = model_z_range(name)
    assert 0.0 <= z0 < z1 < 2.5
    if name != "painting":
        assert z0 < 0.02, f"{name} floats {z0} m above the floor"
    assert poly.contains(poly.centroid) and abs(poly.centroid.x) < 0.2 and abs(poly.centroid.y) < 0.2


def extent(name):
    fp = model_footprint(name)
    z0, z1 = model_z_range(name)
    return np.ptp(fp[:, 0]), np.ptp(fp[:, 1]), z1


def test_sizes_follow_the_papers_apartment():
    # (x, y, z) extents, spec §5
    assert extent("table") == pytest.approx((1.0, 1.8, 0.74), abs=0.01)
    assert extent("sofa") == pytest.approx((1.0, 1.8, 0.8), abs=0.01)
    assert extent("armchair") == pytest.approx((1.0, 1.1, 0.8), abs=0.01)
    assert extent("bookshelf") == pytest.approx((0.4, 1.0, 2.32), abs=0.01)
    assert extent("door")[1] == pytest.approx(1.0) and extent("door")[0] == pytest.approx(0.3)
    assert extent("soccer_ball") == pytest.approx((0.225, 0.225, 0.225), abs=0.003)
    assert extent("rubber_duck") == pytest.approx((0.11, 0.075, 0.10), abs=0.01)
    assert extent("dog")[1] == pytest.approx(0.27, abs=0.01) and 0.9 < extent("dog")[0] < 1.1 and 0.65 < extent("dog")[2] < 0.8
    assert 1.75 < extent("person")[2] < 1.85
    assert 0.75 < extent("fire_extinguisher")[2] < 0.85
    assert 0.9 < extent("potted_flowers")[2] < 1.0
    assert 0.85 < extent("gnome")[2] < 0.95
    assert extent("fridge") == pytest.approx((0.7, 0.7, 1.8), abs=0.04)


def test_duck_is_below_the_lidar_plane():
    assert model_z_range("rubber_duck")[1] < LIDAR_Z
    assert section_at("rubber_duck", LIDAR_Z).is_empty


@pytest.mark.parametrize("name", sorted(MODELS))
def test_legged_models_have_separate_legs_at_lidar_height(name):
    sec = section_at(name, LIDAR_Z)
    parts = list(getattr(sec, "geoms", [sec])) if not sec.is_empty else []
    if get_model(name).legged:
        assert len(parts) >= 2, f"{name}: {len(parts)} piece(s) at {LIDAR_Z} m"
        assert all(p.area < 0.03 for p in parts)
    elif name in ("armchair", "sofa", "bookshelf", "fridge", "kitchen_counter", "fire_extinguisher", "potted_flowers"):
        assert len(parts) >= 1 and sec.area > 0.01


def test_legs_as_in_the_paper():
    dog = section_at("dog", LIDAR_Z)
    assert len(dog.geoms) == 4
    # front pair and rear pair merge at the paper's 0.2 m island linking distance: 2 clusters
    islands = unary_union([g.buffer(0.1) for g in dog.geoms])
    assert len(getattr(islands, "geoms", [islands])) == 2
    table = section_at("table", LIDAR_Z)
    assert len(table.geoms) == 4 and all(g.area == pytest.approx(0.01, rel=0.01) for g in table.geoms)
    person = section_at("person", LIDAR_Z)
    assert len(person.geoms) == 2
    assert len(getattr(unary_union([g.buffer(0.1) for g in person.geoms]), "geoms", [0])) == 1  # one merged cluster
    shelf = section_at("bookshelf", LIDAR_Z)
    # the U: back and two sides, one connected outline enclosing an open box
    assert shelf.geom_type == "Polygon" and shelf.area == pytest.approx(0.0352, abs=1e-3)
    assert shelf.convex_hull.area > 10 * shelf.area


def test_pybullet_bodies_match_the_trimesh_geometry():
    """Vertical rays on a 2 cm grid over the pybullet bodies: every hit lies inside the trimesh
    footprint (same transforms and rpy conventions) and the highest hit is the model's height."""
    import pybullet as p
    from shapely import affinity, contains_xy

    cid = p.connect(p.DIRECT)
    try:
        for name in sorted(MODELS):
            yaw, ox, oy = 0.6, 1.0, -2.0
            bodies = build_model_pybullet(cid, name, ox, oy, yaw)
            assert bodies
            fp = Polygon(model_footprint(name))
            fpw = affinity.translate(affinity.rotate(fp, yaw, origin=(0, 0), use_radians=True), ox, oy)
            x0, y0, x1, y1 = fpw.buffer(0.1).bounds
            gx, gy = np.meshgrid(np.arange(x0, x1, 0.02), np.arange(y0, y1, 0.02))
            frm = np.c_[gx.ravel(), gy.ravel(), np.full(gx.size, 3.0)]
            to = frm.copy()
            to[:, 2] = 0.0005
            hits = []
            for k in range(0, len(frm), 8000):
                for h in p.rayTestBatch(frm[k:k + 8000].tolist(), to[k:k + 8000].tolist(), physicsClientId=cid):
                    if h[0] >= 0:
                        hits.append(h[3])
            hits = np.asarray(hits)
            assert len(hits) > 10, name
            inside = contains_xy(fpw.buffer(0.015), hits[:, 0], hits[:, 1])
            assert inside.mean() > 0.995, f"{name}: {1 - inside.mean():.1%} of pybullet hits outside the footprint"
            z0, z1 = model_z_range(name)
            assert hits[:, 2].max() == pytest.approx(z1, abs=0.035), name  # a cone apex falls between rays
            # and the footprint is covered: the hits' hull fills most of it
            from shapely import MultiPoint

            assert MultiPoint(hits[:, :2]).convex_hull.area > 0.6 * fpw.area, name
            for b, _ in bodies:
                p.removeBody(b, physicsClientId=cid)
    finally:
        p.disconnect(cid)


def test_lidar_rays_see_the_legs_in_pybullet():
    import pybullet as p

    cid = p.connect(p.DIRECT)
    try:
        build_model_pybullet(cid, "table", 0.0, 0.0, 0.0)
        # a ray along y at x = 0.45 (a leg column) hits the leg at y = -0.9; at x = 0 it passes under the top
        hit = p.rayTest([0.45, -3, LIDAR_Z], [0.45, 3, LIDAR_Z], physicsClientId=cid)[0]
        assert hit[0] >= 0 and hit[3][1] == pytest.approx(-0.9, abs=1e-3)
        assert p.rayTest([0.0, -3, LIDAR_Z], [0.0, 3, LIDAR_Z], physicsClientId=cid)[0][0] == -1
    finally:
        p.disconnect(cid)


def test_colors():
    assert parse_color("#ff8000") == pytest.approx((1.0, 128 / 255, 0.0))
    assert parse_color([255, 0, 0]) == (1.0, 0.0, 0.0)
    assert parse_color([0.2, 0.4, 0.6]) == (0.2, 0.4, 0.6)
    for bad in ("#12345", [1, 2], [0, 0, 300], [0, -1, 0], "red", [True, 0, 0]):
        with pytest.raises(ValueError):
            parse_color(bad)
    rng = np.random.default_rng(0)
    cs = [jitter_color((0.8, 0.2, 0.1), rng, 0.1) for _ in range(100)]
    assert all(0 <= v <= 1 for c in cs for v in c)
    assert len(set(cs)) == 100 and np.abs(np.array(cs) - (0.8, 0.2, 0.1)).max() < 0.25


def test_trimesh_visuals_and_world_meshes():
    for name in MODELS:
        m = model_trimesh(name, color=(0.1, 0.9, 0.1))
        assert len(m.faces) > 0 and m.visual.face_colors.shape == (len(m.faces), 4)
    from app.world.format import load_world

    meshes = world_visual_meshes(load_world("assets/worlds/apartment.yaml"))
    names = [n for n, _ in meshes]
    assert names[0] == "floor" and sum(n.startswith("wall_") for n in names) == 5 and sum(n.startswith("object_") for n in names) == 14


def test_object_meshes_are_deterministic(tmp_path):
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_object_meshes", Path("scripts/make_object_meshes.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    written = mod.write(tmp_path)
    assert written
    for p in written:
        committed = MESH_DIR / p.name
        assert committed.read_bytes() == p.read_bytes(), f"{p.name} differs from the committed file: rerun the script"
        m = trimesh.load(committed, force="mesh")
        assert m.is_watertight or p.name == "flower_head.obj"
        assert len(m.faces) < 1000
