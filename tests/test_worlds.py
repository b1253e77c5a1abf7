"""World files: the apartment, YAML round trip, validation errors naming the entry, random worlds."""

from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import example, given, settings
from hypothesis import strategies as st

from app.cli import main as cli_main
from app.config import Config
from app.ocslam.messages import CLASS_NAMES
from app.world.format import dump_world, load_world, world_from_dict, world_to_dict
from app.world.generator import random_world
from app.world.types import ROBOT_RADIUS_M, WorldError, class_counts
from app.world.validation import validate_world

APARTMENT = Path("assets/worlds/apartment.yaml")


@pytest.fixture(scope="module")
def apartment_dict() -> dict:
    return yaml.safe_load(APARTMENT.read_text())


def test_apartment_has_all_classes_and_the_papers_layout():
    w = load_world(APARTMENT)
    counts = class_counts(w)
    assert all(counts[c] >= 1 for c in CLASS_NAMES), counts
    assert counts["door"] == 2 and counts["chair"] == 3
    assert (w.start.x, w.start.y) == (-0.743, -1.199) and w.start.yaw == pytest.approx(-math.pi / 2)
    xmin, ymin, xmax, ymax = w.bounds()
    assert (xmin, ymin, xmax, ymax) == pytest.approx((-10.05, -6.75, 0.15, 0.15))
    table = next(o for o in w.objects if o.label == "table")
    xs, ys = table.footprint()[:, 0], table.footprint()[:, 1]
    assert (xs.min(), xs.max(), ys.min(), ys.max()) == pytest.approx((-1.974, -0.174, -5.444, -4.444), abs=1e-3)
    s1 = next(o for o in w.objects if o.name == "sofa S1")
    fp = s1.footprint()
    assert (fp[:, 0].min(), fp[:, 0].max(), fp[:, 1].min(), fp[:, 1].max()) == pytest.approx((-7.953, -6.153, -1.304, -0.304), abs=0.01)
    assert "tour" in w.routes and len(w.routes["tour"]) >= 10


def _load_dict(d: dict, tmp_path: Path, name: str = "w.yaml"):
    p = tmp_path / name
    p.write_text(yaml.safe_dump(d))
    return load_world(p)


def test_round_trip(tmp_path):
    w = load_world(APARTMENT)
    text = dump_world(w, tmp_path / "a.yaml")
    w2 = load_world(tmp_path / "a.yaml")
    assert world_to_dict(w2) == world_to_dict(w)
    assert "yaw: 132.1" in text  # degrees in YAML


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda d: d["objects"][1].pop("x"), "objects[1] (class 'dog'): missing field 'x'"),
        (lambda d: d["objects"][2].update({"class": "elf"}), "objects[2] (class 'elf'): unknown class 'elf'"),
        (lambda d: d["objects"][2].update({"model": "garden_elf"}), "objects[2] (class 'gnome'): unknown model 'garden_elf'"),
        (lambda d: d["objects"][1].update({"model": "table"}), "objects[1] (class 'dog'): model 'table' is of class 'table', not 'dog'"),
        (lambda d: d["objects"][1].update({"y": -0.2}), "objects[1] (class 'dog', 'dog'): overlaps walls[0] ('north')"),
        (lambda d: d["objects"][0].update({"x": -5.6, "y": -3.8}), "objects[9] (class 'chair', 'armchair'): overlaps objects[0] (class 'ball', 'ball')"),
        (lambda d: d["objects"][0].update({"x": -1.97, "y": -0.6}), "objects[0] (class 'ball', 'ball'): overlaps obstacles[1] ('kitchen run')"),
        (lambda d: d["start"].update({"x": -0.5, "y": -0.5}), "start: the robot at (-0.500, -0.500) overlaps obstacles[0] ('fridge')"),
        (lambda d: d["routes"]["tour"].insert(3, [-3.3, -2.0]), "routes['tour'][3]: waypoint (-3.300, -2.000) is 0.000 m from walls[4] ('partition')"),
        (lambda d: d["routes"]["tour"].insert(1, [-4.5, -1.0]), "routes['tour']: segment [0] → [1] passes 0.000 m from walls[4] ('partition')"),
        (lambda d: d["objects"][3].update({"colour": [1, 0, 0]}), "objects[3] (class 'table'): unknown field(s) 'colour'"),
        (lambda d: d["objects"][3].update({"color": [1, 0]}), "objects[3] (class 'table'): 'color': colour [1, 0]: expected [r, g, b] or '#rrggbb'"),
        (lambda d: d["walls"][0]["openings"][0].update({"end": 11.0}), "walls[0] ('north').openings[0]: [7.9, 11.0] must lie within the wall"),
        (lambda d: d["walls"][2].pop("to"), "walls[2]: missing field 'to'"),
        (lambda d: d.pop("start"), "missing field 'start'"),
        (lambda d: d["obstacles"][0].update({"model": "dog"}), "obstacles[0]: model 'dog' is of class 'dog'; put classified models under 'objects'"),
        (lambda d: d["objects"][5].update({"scale": -1}), "objects[5] (class 'door'): 'scale' must be > 0"),
    ],
)
def test_validation_errors_name_the_entry(apartment_dict, tmp_path, mutate, message):
    d = copy.deepcopy(apartment_dict)
    mutate(d)
    with pytest.raises(WorldError) as e:
        _load_dict(d, tmp_path)
    assert message in str(e.value)
    assert str(tmp_path / "w.yaml") in str(e.value)
    assert isinstance(e.value, ValueError)


def test_malformed_and_missing_files(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("walls: [\n  {from: [0, 0]\n")
    with pytest.raises(WorldError, match="malformed YAML"):
        load_world(bad)
    with pytest.raises(WorldError, match="cannot read world file"):
        load_world(tmp_path / "nope.yaml")
    (tmp_path / "list.yaml").write_text("- 1\n- 2\n")
    with pytest.raises(WorldError, match="expected a mapping"):
        load_world(tmp_path / "list.yaml")


def test_door_fills_its_opening_but_not_a_solid_wall(apartment_dict, tmp_path):
    d = copy.deepcopy(apartment_dict)
    # move door D1 0.5 m along the west wall: half of it is now inside solid wall
    d["objects"][4]["y"] = -4.45
    with pytest.raises(WorldError, match=r"objects\[4\] \(class 'door', 'door D1'\): overlaps walls\[3\] \('west'\)"):
        _load_dict(d, tmp_path)


def test_random_world_is_valid_deterministic_and_varied():
    a, b, c = random_world(11), random_world(11), random_world(12)
    assert world_to_dict(a) == world_to_dict(b)
    assert world_to_dict(a) != world_to_dict(c)
    for w in (a, c):
        validate_world(w)  # raises on any overlap or blocked route segment
        counts = class_counts(w)
        assert all(counts[k] >= 1 for k in CLASS_NAMES), counts
        assert len(w.routes["tour"]) >= 3
        colors = {o.color for o in w.objects if o.color is not None}
        assert len(colors) >= 5


def test_random_world_route_is_collision_free_in_the_simulator():
    """Independent of the shapely check: the pybullet collision probe along every segment."""
    from app.sim_world import SimWorld

    w = random_world(5)
    sim = SimWorld(w, Config(), seed=0)
    try:
        pts = [(w.start.x, w.start.y)] + list(w.routes["tour"])
        checked = 0
        for (x0, y0), (x1, y1) in zip(pts, pts[1:]):
            n = max(2, int(math.hypot(x1 - x0, y1 - y0) / 0.05))
            for t in np.linspace(0, 1, n):
                assert sim.pose_free(x0 + t * (x1 - x0), y0 + t * (y1 - y0)), f"route blocked near ({x0:.2f}, {y0:.2f})"
                checked += 1
        assert checked > 50
        # every room is visited: the route reaches at least 3 distinct rooms' worth of area
        route = np.asarray(pts)
        assert np.ptp(route[:, 0]) > 2.0 and np.ptp(route[:, 1]) > 1.5
    finally:
        sim.close()


SQUARE = [{"from": [0, 0], "to": [4, 0]}, {"from": [4, 0], "to": [4, 4]}, {"from": [4, 4], "to": [0, 4]},
          {"from": [0, 4], "to": [0, 0]}]


def test_world_from_dict_defaults():
    w = world_from_dict(
        {
            "walls": SQUARE,
            "objects": [{"class": "duck", "model": "rubber_duck", "x": 1, "y": 1}],
            "start": {"x": 2, "y": 2},
        }
    )
    assert w.walls[0].thickness == 0.15 and w.walls[0].height == 2.4
    assert w.objects[0].yaw == 0.0 and w.objects[0].scale == 1.0 and w.start.yaw == 0.0
    validate_world(w)
    assert w.walls[0].solid_polygon().area == pytest.approx(4 * 0.15)


@pytest.mark.parametrize("walls, obj, start, message", [
    (SQUARE[:1], (1, 1), (2, 2), "objects[0] (class 'duck'): at (1.000, 1.000) is outside every room (the walls enclose no area)"),
    (SQUARE, (6, 1), (2, 2), "objects[0] (class 'duck'): at (6.000, 1.000) is outside every room"),
    (SQUARE, (1, 1), (5, 2), "start: the robot at (5.000, 2.000) is outside the walls"),
    (SQUARE, (1, 1), (-2, -2), "start: the robot at (-2.000, -2.000) is outside the walls"),
])
def test_objects_and_start_must_be_inside_the_walls(walls, obj, start, message):
    w = world_from_dict({"walls": walls, "objects": [{"class": "duck", "model": "rubber_duck", "x": obj[0], "y": obj[1]}],
                         "start": {"x": start[0], "y": start[1]}})
    with pytest.raises(WorldError) as e:
        validate_world(w)
    assert message in str(e.value)


def test_a_door_in_an_outer_wall_and_an_open_doorway_are_inside():
    walls = copy.deepcopy(SQUARE)
    walls[0]["openings"] = [{"kind": "door", "start": 1.0, "end": 2.0}]
    walls[2]["openings"] = [{"kind": "passage", "start": 1.0, "end": 2.0}]
    w = world_from_dict({"walls": walls, "objects": [{"class": "door", "model": "door", "x": 1.5, "y": 0.0, "yaw": 90}],
                         "start": {"x": 2, "y": 2}})
    validate_world(w)


@pytest.mark.parametrize("seed", [3, 99000])
def test_random_worlds_validate_under_the_room_rule(seed):
    validate_world(random_world(seed))


def _big_world(n_objects: int, n_walls: int = 4) -> dict:
    side = 200.0
    walls = [{"from": [0, 0], "to": [side, 0]}, {"from": [side, 0], "to": [side, side]},
             {"from": [side, side], "to": [0, side]}, {"from": [0, side], "to": [0, 0]}]
    walls += [{"from": [10.0 + 0.3 * k, 190.0], "to": [10.0 + 0.3 * k, 195.0], "thickness": 0.05} for k in range(n_walls - 4)]
    k = int(math.ceil(math.sqrt(n_objects)))
    objects = [{"class": "duck", "model": "rubber_duck", "x": 5.0 + 1.0 * (i % k), "y": 5.0 + 1.0 * (i // k)} for i in range(n_objects)]
    return {"walls": walls, "objects": objects, "start": {"x": 150.0, "y": 150.0},
            "routes": {"tour": [[150.0, 120.0], [120.0, 120.0]]}}


def test_a_world_at_the_limits_validates_quickly(tmp_path):
    import time

    from app.world.validation import MAX_ENTITIES, MAX_WALLS

    p = tmp_path / "big.yaml"
    p.write_text(yaml.safe_dump(_big_world(MAX_ENTITIES, MAX_WALLS)))
    t0 = time.perf_counter()
    w = load_world(p)
    assert len(w.objects) == MAX_ENTITIES and len(w.walls) == MAX_WALLS
    assert time.perf_counter() - t0 < 30.0  # a loose bound (shared CPU); 10,000 objects once took 48 s


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d["objects"].extend(d["objects"][:2]), "501 objects and 0 obstacles; a world may have at most 500"),
    (lambda d: d["walls"].extend(d["walls"][:1] * 497), "walls: 501 walls; a world may have at most 500"),
    (lambda d: d["objects"][0].update({"x": 501.0}), "objects[0] (class 'duck'): 'x' is 501.0; coordinates are limited to ±500 m"),
    (lambda d: d["walls"][0].update({"to": [-600, 0]}), "walls[0]: 'to' is -600; coordinates are limited to ±500 m"),
    (lambda d: d.update({"obstacles": [{"shape": "box", "x": 50, "y": 50, "size": [60, 1, 1]}]}),
     "obstacles[0]: 'size' is 60; sizes are limited to 50 m"),
    (lambda d: d["objects"][0].update({"scale": 1000}), "objects[0] (class 'duck'): 'scale' 1000 makes 'rubber_duck'"),
    (lambda d: d["start"].update({"x": float("nan")}), "start: 'x' must be a finite number, got nan"),
])
def test_world_limits_are_checked_before_anything_heavy(tmp_path, mutate, message):
    d = _big_world(499)
    mutate(d)
    p = tmp_path / "w.yaml"
    p.write_text(yaml.safe_dump(d))
    with pytest.raises(WorldError) as e:
        load_world(p)
    assert message in str(e.value)


def test_binary_and_huge_world_files_are_refused(tmp_path):
    from app.world.validation import MAX_FILE_BYTES

    b = tmp_path / "bin.yaml"
    b.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(WorldError, match="not a world file"):
        load_world(b)
    h = tmp_path / "huge.yaml"
    h.write_bytes(b"#" * (MAX_FILE_BYTES + 1))
    with pytest.raises(WorldError, match="world files are limited to"):
        load_world(h)


def test_window_is_solid_at_lidar_height_and_door_opening_is_not(tmp_path):
    w = load_world(APARTMENT)
    east = w.walls[1]
    assert east.solid_polygon(0.173).area == pytest.approx(east.polygon().area)
    assert east.solid_polygon(1.5).area < east.polygon().area - 0.25
    west = w.walls[3]
    assert west.solid_polygon(0.173).area == pytest.approx(west.polygon().area - 1.0 * 0.3)


def test_cli_random_and_validate(tmp_path, capsys):
    out = tmp_path / "r.yaml"
    assert cli_main(["world", "random", "--seed", "3", "--out", str(out)]) == 0
    assert cli_main(["world", "validate", str(out), str(APARTMENT)]) == 0
    text = capsys.readouterr().out
    assert "OK" in text and "tour" in text
    d = yaml.safe_load(out.read_text())
    d["objects"][0]["class"] = "unicorn"
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump(d))
    assert cli_main(["world", "validate", str(tmp_path / "bad.yaml")]) == 2
    assert "unknown class 'unicorn'" in capsys.readouterr().err
    assert ROBOT_RADIUS_M == Config().robot.footprint_radius_m


def test_documented_example_and_bundled_worlds_are_valid():
    import re

    text = Path("docs/world-format.md").read_text()
    example = re.search(r"```yaml\n(.*?)```", text, re.S).group(1)
    w = world_from_dict(yaml.safe_load(example), "docs/world-format.md")
    assert {o.label for o in w.objects} == {"dog", "chair", "door", "ball"}
    for f in sorted(Path("assets/worlds").glob("*.yaml")):
        load_world(f)
    validate_world(w)  # objects and the start inside the example room's walls



@settings(max_examples=60, deadline=None)
@given(
    length=st.floats(1.0, 12.0),
    height=st.floats(1.0, 3.0),
    cuts=st.lists(st.tuples(st.floats(0.0, 1.0), st.floats(0.05, 0.3), st.floats(0.0, 0.8), st.floats(0.1, 1.0)), max_size=4),
)
def test_wall_pieces_and_openings_tile_the_wall(length, height, cuts):
    """Solid pieces plus openings cover the wall's face exactly once (area L·H), for any openings."""
    from app.world.types import Opening, Wall

    openings, s = [], 0.0
    for frac, width, bottom, top in cuts:
        s0 = s + frac * 0.3 * length
        s1 = s0 + width * length
        if s1 > length:
            break
        z0 = bottom * height * 0.5
        z1 = z0 + (height - z0) * top
        if z1 - z0 < 1e-3:
            continue
        openings.append(Opening(s0, s1, z0, z1, "window"))
        s = s1
    w = Wall((0.0, 0.0), (length, 0.0), 0.2, height, tuple(openings))
    pieces = w.boxes()
    area = sum((s1 - s0) * (z1 - z0) for s0, s1, z0, z1, _, _ in pieces)
    holes = sum((o.end - o.start) * (o.top - o.bottom) for o in openings)
    assert area + holes == pytest.approx(length * height, rel=1e-9)
    for s0, s1, z0, z1, _th, _yaw in pieces:
        assert 0 <= s0 < s1 <= length + 1e-9 and 0 <= z0 < z1 <= height + 1e-9
        for o in openings:  # no piece intrudes into an opening
            assert min(s1, o.end) - max(s0, o.start) <= 1e-9 or min(z1, o.top) - max(z0, o.bottom) <= 1e-9


@settings(max_examples=40, deadline=None)
@given(st.integers(min_value=0, max_value=10_000), st.sampled_from(["rooms", "corridor", "lshape", "openplan"]))
@example(4551, "lshape")  # an outer wall exactly a window plus 1.4 m long: the window's range rounded below zero
def test_bounds_are_the_union_bounds(seed: int, family: str) -> None:
    """World.bounds (the extremes of the parts' bounds) equals the bounds of the parts' union."""
    from shapely.geometry import Polygon
    from shapely.ops import unary_union

    w = random_world(seed, family=family)
    parts = [x.polygon() for x in w.walls] + [Polygon(o.footprint()) for o in w.objects + w.obstacles]
    np.testing.assert_allclose(w.bounds(), unary_union(parts).bounds, atol=1e-12)
