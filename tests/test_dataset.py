"""The rendered YOLO dataset: split by world, YOLO files consistent with the COCO annotations."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from app.ocslam.messages import CLASS_NAMES
from app.training.dataset import DatasetOptions, build_dataset, parse_imgsz, plan_worlds
from app.training.labels import LabelFilter
from app.training.randomization import make_texture, sensor_effects
from app.training.samples import load_samples


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 10_000), st.integers(0, 60), st.floats(0.0, 1.0), st.booleans())
def test_plan_splits_by_world(seed: int, n: int, frac: float, apartment: bool) -> None:
    tasks = plan_worlds(DatasetOptions(out=Path("x"), worlds=n, seed=seed, val_fraction=frac, apartment=apartment))
    keys = [(t.kind, t.world_seed) for t in tasks]
    assert len(set(keys)) == len(keys)  # every world once, so in exactly one split
    assert {t.split for t in tasks} <= {"train", "val"}
    assert all(t.split == "train" for t in tasks if t.kind == "apartment")
    n_val = sum(t.split == "val" for t in tasks)
    if 0 < frac < 1 and n >= 2:
        assert 1 <= n_val <= n - 1  # both splits exist
    # Datasets with other seeds never share a random world.
    other = plan_worlds(DatasetOptions(out=Path("x"), worlds=n, seed=seed + 1))
    assert not {t.world_seed for t in tasks if t.kind == "random"} & {t.world_seed for t in other if t.kind == "random"}


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 40), st.lists(st.sampled_from(["rooms", "corridor", "lshape", "openplan"]), min_size=1, max_size=4))
def test_plan_cycles_the_layout_families(n: int, families: list[str]) -> None:
    tasks = plan_worlds(DatasetOptions(out=Path("x"), worlds=n, seed=3, families=tuple(families), apartment=False))
    assert [t.family for t in tasks] == [families[i % len(families)] for i in range(n)]
    # the families do not change which worlds (seeds) or which split: only their layouts
    plain = plan_worlds(DatasetOptions(out=Path("x"), worlds=n, seed=3, families=("rooms",), apartment=False))
    assert [(t.world_seed, t.split) for t in tasks] == [(t.world_seed, t.split) for t in plain]


def test_parse_imgsz() -> None:
    assert parse_imgsz("320x240") == (320, 240)
    assert parse_imgsz("640×480") == (640, 480)
    with pytest.raises(ValueError):
        parse_imgsz("320")


def test_textures_and_sensor_effects_are_images() -> None:
    rng = np.random.default_rng(0)
    for kind in ("planks", "tiles", "checker", "carpet", "stripes", "marble", "plain"):
        t = make_texture(kind, rng, 64)
        assert t.shape == (64, 64, 3) and t.dtype == np.uint8
    img = np.full((24, 32, 3), 128, np.uint8)
    out = sensor_effects(img, rng)
    assert out.shape == img.shape and out.dtype == np.uint8 and not np.array_equal(out, img)


def test_sensor_effects_match_the_pointwise_chain_with_noise_on_every_channel() -> None:
    """Known answer on a flat image (blur keeps it flat): each channel's mean is the contrast, gain and
    gamma chain of the draws taken in the same order, its spread the drawn noise sigma; same seed, same image."""
    img = np.full((120, 160, 3), (30, 90, 150), np.uint8)  # never saturated by the draws
    for seed in range(6):
        ref = np.random.default_rng(seed)
        gain = ref.uniform(0.75, 1.25) * ref.uniform(0.93, 1.07, 3)
        contrast, gamma = ref.uniform(0.8, 1.2), ref.uniform(0.8, 1.25)
        r = ref.random()
        if r < 0.25:
            ref.uniform(0.4, 1.2)
        elif r < 0.35:
            ref.integers(3, 8)
            ref.random()
        sigma = ref.uniform(0.5, 7.0)
        v = np.array([30, 90, 150]) / 255.0
        want = np.clip(np.clip((v - 0.5) * contrast + 0.5, 0, 1) * gain, 0, 1) ** gamma * 255.0
        out = sensor_effects(img, np.random.default_rng(seed)).astype(float)
        assert np.array_equal(out, sensor_effects(img, np.random.default_rng(seed)))
        inner = out[8:-8, 8:-8]  # away from the blur's border
        np.testing.assert_allclose(inner.mean(axis=(0, 1)), want, atol=0.6)
        if r >= 0.35:  # no blur: the noise is the drawn sigma on each channel (clipping aside)
            np.testing.assert_allclose(inner.std(axis=(0, 1)), sigma, rtol=0.15, atol=0.35)


def test_dataset_images_stored_or_compressed_hold_the_same_pixels(tmp_path: Path) -> None:
    from app.training.dataset import png_flags

    rng = np.random.default_rng(3)
    img = np.clip(rng.normal(120.0, 30.0, (48, 64, 3)), 0, 255).astype(np.uint8)  # a noisy render
    sizes = {}
    for compress in (False, True):
        f = tmp_path / f"{compress}.png"
        assert cv2.imwrite(str(f), img, png_flags(compress))
        np.testing.assert_array_equal(cv2.imread(str(f), cv2.IMREAD_UNCHANGED), img)
        sizes[compress] = f.stat().st_size
    assert sizes[False] >= img.nbytes > sizes[True]


@pytest.mark.slow
def test_small_dataset_is_split_by_world_and_consistent(tmp_path: Path) -> None:
    out = tmp_path / "ds"
    meta = build_dataset(
        DatasetOptions(
            out=out, worlds=3, per_world=3, seed=5, imgsz=(160, 120), workers=1, val_fraction=0.34,
            apartment=True, apartment_images=2, label_filter=LabelFilter(), command="test",
        ),
        progress=False,
    )
    assert meta["images"] == {"train": 8, "val": 3}
    # world i is of family i mod 4 (the default: every layout family)
    assert meta["families"] == ["rooms", "corridor", "lshape", "openplan"]
    worlds = set(meta["train_worlds"]) | set(meta["val_worlds"])
    assert worlds == {"apartment", "random_world(5000)", "random_world(5001, family='corridor')",
                      "random_world(5002, family='lshape')"}
    assert not set(meta["train_worlds"]) & set(meta["val_worlds"])
    assert "apartment" in meta["train_worlds"] and len(meta["val_worlds"]) == 1
    data = yaml.safe_load((out / "data.yaml").read_text())
    assert [data["names"][i] for i in range(len(CLASS_NAMES))] == list(CLASS_NAMES)
    assert data["ocslam"]["command"] == "test" and data["ocslam"]["seed"] == 5
    for split in ("train", "val"):
        coco = json.loads((out / f"annotations_{split}.json").read_text())
        worlds = {im["world"] for im in coco["images"]}
        assert worlds == set(meta[f"{split}_worlds"])
        kept: dict[int, int] = {}
        for a in coco["annotations"]:
            kept[a["image_id"]] = kept.get(a["image_id"], 0) + (a["iscrowd"] == 0)
            assert a["iscrowd"] == 1 or a["visible_fraction"] >= 0.35
        for im in coco["images"]:
            img = out / im["file_name"]
            assert img.exists()
            lbl = out / "labels" / split / (img.stem + ".txt")
            rows = [r.split() for r in lbl.read_text().splitlines() if r.strip()]
            assert len(rows) == kept.get(im["id"], 0)
            for r in rows:
                assert 0 <= int(r[0]) < len(CLASS_NAMES)
                assert all(0.0 <= float(v) <= 1.0 for v in r[1:])
    samples = load_samples(out, "all")
    assert len(samples) == 11 and samples[0].load().shape == (120, 160, 3)
    # stored uncompressed by default: at least the raw pixels' bytes
    assert all(f.stat().st_size >= 160 * 120 * 3 for f in (out / "images").glob("*/*.png"))


def test_overlay_mesh_file_known_answer(tmp_path: Path) -> None:
    from app.training.randomization import quad_obj_geometry, write_mesh_obj

    quads = [(np.zeros(3), np.array([2.0, 0, 0]), np.array([0, 1.0, 0]), 0.5)]
    obj = write_mesh_obj(quad_obj_geometry(quads), tmp_path / "q.obj", material="q.mtl")
    lines = obj.read_text().splitlines()
    assert "mtllib q.mtl" in lines and "usemtl m" in lines
    v = [[float(x) for x in ln.split()[1:]] for ln in lines if ln.startswith("v ")]
    vt = [[float(x) for x in ln.split()[1:]] for ln in lines if ln.startswith("vt ")]
    vn = [[float(x) for x in ln.split()[1:]] for ln in lines if ln.startswith("vn ")]
    assert v == [[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]]
    assert vt == [[0, 0], [4, 0], [4, 2], [0, 2]]  # the texture repeats every 0.5 m
    assert vn == [[0, 0, 1]] * 4
    assert [ln for ln in lines if ln.startswith("f ")] == ["f 1/1/1 2/2/2 3/3/3", "f 1/1/1 3/3/3 4/4/4"]


@pytest.mark.slow
@pytest.mark.parametrize("renderer", ["tiny", "egl"])
def test_randomised_floor_is_textured_in_both_renderers(renderer: str, tmp_path: Path) -> None:
    """The floor overlay shows its texture (a checkerboard's two colours) in TinyRenderer and in the
    app's EGL renderer (which ignores a ``textureUniqueId`` set by ``changeVisualShape`` in a busy scene)."""
    from app.config import Config
    from app.ocslam.se2 import Pose2
    from app.sim_world import SimWorld, probe_egl
    from app.training import randomization
    from app.training.randomization import Randomizer
    from app.world.generator import random_world

    if renderer == "egl" and not probe_egl()[0]:
        pytest.skip("EGL does not load here")
    world = random_world(7000)
    sim = SimWorld(world, Config(), seed=7000, renderer=renderer)
    try:
        rz = Randomizer(sim, np.random.default_rng(0), tmp_path, (0, 0))
        kinds = randomization.TEXTURE_KINDS
        randomization.TEXTURE_KINDS = ("checker",)  # the floor's kinds are read at each randomisation
        try:
            rz.randomize_scene()
        finally:
            randomization.TEXTURE_KINDS = kinds
        o = world.objects[0]
        frame = sim.render_view(Pose2(o.x - 1.5, o.y, 0.0), width=160, height=120, segmentation=False)
        floor = frame.image.data[-15:, :, :].reshape(-1, 3).astype(float)
        assert floor.std(axis=0).max() > 20.0  # two colours, not the plain white of an untextured overlay
    finally:
        sim.close()


def test_urdf_mesh_box_predicts_the_loaded_distractors_bounds(tmp_path: Path) -> None:
    """A distractor's disc is judged before it is loaded: for pybullet_data's random URDFs, loaded turned and
    scaled, the AABB's centre is the predicted one and its half extents are at least the predicted ones (the
    collision margin); URDFs of another build are not predicted."""
    import math

    import pybullet as p
    import pybullet_data

    from app.training.randomization import _distractor_urdfs, urdf_mesh_box

    urdfs = _distractor_urdfs(pybullet_data.getDataPath())
    assert len(urdfs) >= 100
    rng = np.random.default_rng(11)
    cid = p.connect(p.DIRECT)
    try:
        for k in rng.choice(len(urdfs), 30, replace=False):
            box = urdf_mesh_box(str(urdfs[k]))
            assert box is not None and box.shape == (2, 2) and np.all(box[1] > box[0])
            s, yaw, (x, y) = float(rng.uniform(2, 7)), float(rng.uniform(-math.pi, math.pi)), rng.uniform(-3, 3, 2)
            b = p.loadURDF(str(urdfs[k]), [x, y, 0.0], p.getQuaternionFromEuler([0, 0, yaw]), globalScaling=s,
                           useFixedBase=True, physicsClientId=cid)
            lo, hi = (np.asarray(v)[:2] for v in p.getAABB(b, -1, physicsClientId=cid))
            R = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
            centre = np.array([x, y]) + R @ (s * box.mean(axis=0))
            half = np.abs(R) @ (s * (box[1] - box[0]) / 2)
            np.testing.assert_allclose((lo + hi) / 2, centre, atol=1e-6)
            assert np.all((hi - lo) / 2 >= half - 1e-9) and np.all((hi - lo) / 2 <= half + 0.02)
    finally:
        p.disconnect(cid)
    joint = tmp_path / "two_links.urdf"
    joint.write_text('<robot name="r"><link name="a"/><link name="b"/>'
                     '<joint name="j" type="fixed"><parent link="a"/><child link="b"/></joint></robot>')
    assert urdf_mesh_box(str(joint)) is None
    assert urdf_mesh_box(str(tmp_path / "missing.urdf")) is None
    (tmp_path / "bad.urdf").write_text("<robot")
    assert urdf_mesh_box(str(tmp_path / "bad.urdf")) is None
    one = ('<robot name="r"><link name="a"><collision><geometry><mesh filename="m.obj" scale="2 2 2"/></geometry>'
           "</collision></link></robot>")
    (tmp_path / "one.urdf").write_text(one)
    (tmp_path / "m.obj").write_text("v 0 0 0\nv 1 -0.5 2\nvn 0 0 1\nf 1 2 1\n")
    np.testing.assert_allclose(urdf_mesh_box(str(tmp_path / "one.urdf")), [[0.0, -1.0], [2.0, 0.0]])
    (tmp_path / "nan.urdf").write_text(one.replace("m.obj", "nan.obj"))
    (tmp_path / "nan.obj").write_text("v 0 0 0\nv nan nan nan\n")  # as pybullet_data's random_urdfs/168
    assert urdf_mesh_box(str(tmp_path / "nan.urdf")) is None
