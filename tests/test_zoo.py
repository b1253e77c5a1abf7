"""The world zoo, the layout families, the benchmark suites and the causes of missed objects (issue 9)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from shapely.geometry import LineString, Point
from shapely.ops import unary_union

from app.ocslam.evaluation import MISS_CAUSES, ObservationLog, evaluate_objects, explain_misses
from app.ocslam.messages import CLASS_NAMES, GroundTruthObject, TrackedObject
from app.ocslam.se2 import Pose2
from app.ocslam.visibility import image_columns, in_view_matrix
from app.world.format import dump_world, load_world, world_to_dict
from app.world.generator import FAMILIES, generate
from app.world.tour import route_poses, tour_view_counts
from app.world.types import ROBOT_RADIUS_M, ROUTE_MARGIN_M
from app.world.validation import validate_world

ROOT = Path(__file__).resolve().parents[1]
ZOO_DIR = ROOT / "assets" / "worlds" / "zoo"
ZOO = sorted(p for p in ZOO_DIR.glob("*.yaml") if p.name != "split.yaml")
MIN_VIEWS = 10


# ----------------------------------------------------------------------------------------------
# The zoo
# ----------------------------------------------------------------------------------------------


def test_the_zoo_has_16_worlds_split_in_two_documented_halves():
    from app.bench.objects import suite_jobs, zoo_split

    names = {p.stem for p in ZOO}
    assert len(names) >= 16
    split = zoo_split()
    dev, test = set(split["dev"]), set(split["test"])
    assert not dev & test
    assert dev | test == names
    # one dev world per kind, and more for each kind whose test world failed (README's rule): never fewer than test
    assert len(test) <= len(dev)
    readme = (ZOO_DIR / "README.md").read_text(encoding="utf-8")
    rows = [line for line in readme.splitlines() if line.startswith("| ") and "`" in line]
    for line in rows:  # a table row: | kind | dev world | test world |
        cells = [c.strip() for c in line.strip("|").split("|")]
        assert cells[1].split("`")[1] in dev and cells[2].split("`")[1] in test, line
    documented = {c.split("`")[1] for line in rows for c in line.strip("|").split("|")[1:3]}
    assert documented == names
    jobs = suite_jobs("zoo-test")
    assert [j["name"] for j in jobs] == split["test"] and all(Path(j["file"]).is_file() for j in jobs)


@pytest.mark.parametrize("path", ZOO, ids=[p.stem for p in ZOO])
def test_zoo_world_loads_and_its_tour_is_free_and_sees_every_object(path: Path):
    first = path.read_text(encoding="utf-8").splitlines()[0]
    assert first.startswith("# ") and len(first) > 40, "each zoo file documents itself in its first line"
    world = load_world(path)  # validates walls, objects and every route segment
    assert world.name == path.stem
    # collision-free: every tour segment keeps the robot radius + margin from everything that blocks it
    blocking = unary_union([g for _, g in world.blocking_geometry()])
    pts = [(world.start.x, world.start.y)] + [tuple(p) for p in world.route("tour")]
    gaps = [blocking.distance(LineString([a, b]) if a != b else Point(a)) for a, b in zip(pts[:-1], pts[1:])]
    assert min(gaps) >= ROBOT_RADIUS_M + ROUTE_MARGIN_M - 1e-9
    assert math.dist(pts[0], pts[-1]) < 0.1, "the tour returns to the start (a loop closure)"
    counts = tour_view_counts(world)
    unseen = [world.object_name(i) for i in np.nonzero(counts < MIN_VIEWS)[0]]
    assert not unseen, f"objects the tour does not bring into view: {unseen}"


def test_the_view_check_is_not_vacuous():
    """A tour that stays at the start and looks one way misses objects behind it."""
    world = load_world(ZOO_DIR / "meeting_room.yaml")
    world.routes = {"tour": [(world.start.x + 0.3, world.start.y)]}
    counts = tour_view_counts(world)
    assert (counts < MIN_VIEWS).any() and (counts >= 1).any()


def test_route_poses_turn_in_place_then_drive():
    world = load_world(ZOO_DIR / "narrow_bedroom.yaml")
    world.routes = {"tour": [(world.start.x, world.start.y + 1.0)]}  # start faces +y already
    world.start = Pose2(world.start.x, world.start.y, 0.0)
    poses = route_poses(world, step_m=0.1, turn_step_rad=0.15)
    n_turn = int((math.pi / 2) / 0.15) + 1  # headings 0, 0.15, …, 1.5 on the spot
    assert np.allclose(poses[:n_turn, 2], 0.15 * np.arange(n_turn)) and np.allclose(poses[:n_turn, :2], poses[0, :2])
    drive = poses[n_turn:]
    assert np.allclose(drive[:, 2], math.pi / 2) and np.allclose(drive[:, 0], world.start.x)
    assert np.diff(drive[:, 1]).max() == pytest.approx(0.1) and drive[-1, 1] == pytest.approx(world.start.y + 1.0)


def test_walls_hide_objects_and_the_field_of_view_limits_them():
    from app.world.types import Wall

    square = lambda x, y, r=0.1: np.array([[x - r, y - r], [x + r, y - r], [x + r, y + r], [x - r, y + r]])  # noqa: E731
    fps = [square(2.0, 0.0), square(2.0, 0.0), square(0.0, 2.0), square(5.0, 0.0)]
    wall = Wall((1.0, -1.0), (1.0, 1.0), 0.1).polygon()
    m = in_view_matrix(np.array([[0.0, 0.0, 0.0]]), fps, [None, wall, None, None], 1.04, max_range_m=4.0)
    assert m.tolist() == [[True, False, False, False]]  # hidden by the wall, outside the FOV, out of range


# ----------------------------------------------------------------------------------------------
# Layout families
# ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("family,seed", [(f, s) for f in sorted(FAMILIES) for s in (3, 99004)])
def test_layout_family_gives_valid_furnished_worlds_with_a_seeing_tour(family: str, seed: int, tmp_path: Path):
    world = generate(family, seed)
    validate_world(world)
    assert world.name == f"{family}_{seed}" and world.seed == seed
    labels = {o.label for o in world.objects}
    assert labels == set(CLASS_NAMES), f"classes missing: {set(CLASS_NAMES) - labels}"
    assert (tour_view_counts(world) >= MIN_VIEWS).all()
    dump_world(world, tmp_path / "w.yaml")
    again = load_world(tmp_path / "w.yaml")
    assert len(again.objects) == len(world.objects) and len(again.walls) == len(world.walls)
    # furniture groups: a table has chairs pushed against it in most worlds; chairs never stand on tables
    tables = [o for o in world.objects if o.label == "table"]
    assert tables


def test_layout_families_are_deterministic_and_differ_from_each_other():
    a, b = generate("lshape", 11), generate("lshape", 11)
    assert world_to_dict(a) == world_to_dict(b)
    c = generate("openplan", 11)
    assert world_to_dict(c)["walls"] != world_to_dict(a)["walls"]
    with pytest.raises(ValueError, match="unknown layout family"):
        generate("castle", 1)


def test_world_random_family_flag(tmp_path: Path, capsys):
    from app.cli import main

    out = tmp_path / "corridor.yaml"
    assert main(["world", "random", "--family", "corridor", "--seed", "5", "--out", str(out)]) == 0
    world = load_world(out)
    assert world.name == "corridor_5" and "corridor" in world.description
    doors = [o for o in world.objects if o.label == "door"]
    assert len(doors) >= 2  # both ends of the corridor


def test_suites_are_seeded_and_summarised():
    from app.bench.objects import RANDOM_FAMILIES, suite_jobs, summarize

    jobs = suite_jobs("random", n_random=10, first_seed=99000)
    assert [j["seed"] for j in jobs] == list(range(99000, 99010))
    assert {j["family"] for j in jobs} == set(RANDOM_FAMILIES) == {"corridor", "lshape", "openplan"}
    assert suite_jobs("random") == jobs
    per_world = [
        {"f1": 1.0, "recall": 1.0, "fp_legs": 1, "fp_corner": 0, "fp_other": 0, "miss_causes": {"merged": 2}},
        {"f1": 0.5, "recall": 0.25, "fp_legs": 0, "fp_corner": 2, "fp_other": 1, "miss_causes": {"merged": 1, "lost": 1}},
        {"error": "RuntimeError: boom", "job": {"name": "x"}},
    ]
    s = summarize(per_world)
    assert s["mean"]["f1"] == pytest.approx(0.75) and s["mean"]["recall"] == pytest.approx(0.625)
    assert s["miss_causes"]["merged"] == 3 and s["miss_causes"]["lost"] == 1 and s["miss_causes"]["never_in_view"] == 0
    assert s["fp_causes"] == {"legs": 1, "corner": 2, "other": 1}
    assert s["worlds_ok"] == 2 and s["worlds_failed"] == 1


# ----------------------------------------------------------------------------------------------
# Causes of misses
# ----------------------------------------------------------------------------------------------


def _rect(x, y, sx, sy):
    return np.array([[x - sx / 2, y - sy / 2], [x + sx / 2, y - sy / 2], [x + sx / 2, y + sy / 2], [x - sx / 2, y + sy / 2]])


def test_image_columns_known_answer():
    cols = image_columns(np.array([0.0, 0.0, 0.0]), _rect(2.0, 1.0, 0.2, 0.2), fx=100.0, cx=160.0, width=320)
    assert cols == pytest.approx((160 - 100 * 1.1 / 1.9, 160 - 100 * 0.9 / 2.1))
    assert image_columns(np.array([0.0, 0.0, math.pi]), _rect(2.0, 1.0, 0.2, 0.2), 100.0, 160.0, 320) is None


def test_every_miss_gets_its_cause_on_a_synthetic_run():
    """Camera at the origin facing +x. Known answers: a door behind the camera is never in view, a
    gnome is never boxed, the flowers' box has no LIDAR return, the chair's points went into the
    table's object, the ball's object stands 0.6 m off, the person's object stayed below the threshold
    and the dog's track was lost."""
    names = ["door", "gnome", "flowers", "chair", "table", "person", "dog", "ball"]
    spec = {"door": (-2.0, 0.0, 0.3, 1.0), "gnome": (2.0, 0.6, 0.25, 0.3), "flowers": (2.5, -0.6, 0.2, 0.2),
            "chair": (3.0, 0.0, 0.5, 0.5), "table": (3.0, 1.2, 1.0, 1.0), "person": (3.5, -1.0, 0.3, 0.6),
            "dog": (2.2, -0.25, 0.25, 0.25), "ball": (3.5, -1.6, 0.22, 0.22)}
    truth = [GroundTruthObject(i, n, Pose2(spec[n][0], spec[n][1], 0.0), _rect(*spec[n]), 0.0, 1.0, name=n)
             for i, n in enumerate(names)]
    pose = np.array([0.0, 0.0, 0.0])
    fx, cx, width = 277.0, 160.0, 320
    iv = in_view_matrix(pose[None], [t.footprint for t in truth], [None] * len(truth), 1.04)[0]
    assert iv.tolist() == [False, True, True, True, True, True, True, True]
    boxes = []
    for t in truth[2:]:
        u0, u1 = image_columns(pose, t.footprint, fx, cx, width)
        boxes.append((t.label, u0 - 2.0, u1 + 2.0))
    scan = np.vstack([_rect(*spec[n])[:2] for n in ("chair", "table", "person", "dog", "ball")])  # returns on their near faces
    log = ObservationLog(len(truth))
    for _ in range(3):
        log.add_frame(pose, truth, iv, boxes, fx, cx, width, scan)
    assert log.in_view.tolist() == [0, 3, 3, 3, 3, 3, 3, 3]
    assert log.detected.tolist() == [0, 0, 3, 3, 3, 3, 3, 3]
    assert log.lidar.tolist() == [0, 0, 0, 3, 3, 3, 3, 3]
    tracked = [
        TrackedObject(1, "table", Pose2(3.0, 0.8, 0.0), 1.0, 1.8, presence=0.95, footprint=_rect(3.0, 0.7, 1.0, 1.8)),
        TrackedObject(2, "person", Pose2(3.55, -1.0, 0.0), 0.3, 0.6, presence=0.5),
        TrackedObject(3, "dog", Pose2(0.5, 2.5, 0.0), 0.3, 0.6, presence=0.3),  # far from the dog: not its track
        TrackedObject(4, "ball", Pose2(4.1, -1.6, 0.0), 0.2, 0.2, presence=0.9),  # 0.6 m off the ball: a false ball
    ]
    report = evaluate_objects(tracked, truth, presence_threshold=0.8)
    assert report.tp == 1 and report.fn == 7 and report.fp_other == 1
    counts = explain_misses(report, truth, tracked, log, presence_threshold=0.8)
    causes = {r["name"]: r["cause"] for r in report.rows if r["kind"] == "truth"}
    assert causes == {"door": "never_in_view", "gnome": "never_detected", "flowers": "no_lidar_support", "chair": "merged",
                      "table": "tp", "person": "below_threshold", "dog": "lost", "ball": "mislocated"}
    assert counts == {"never_in_view": 1, "never_detected": 1, "no_lidar_support": 1, "merged": 1, "mislocated": 1,
                      "below_threshold": 1, "lost": 1}
    assert set(counts) == set(MISS_CAUSES)
    chair_row = next(r for r in report.rows if r["name"] == "chair")
    assert "table #1 (table)" in chair_row["miss_detail"]


def test_a_true_neighbour_beside_a_missed_object_is_no_merge():
    """A table missed and a true chair pushed under its edge (the chair found where it stands): the table was not
    merged into the chair (lost); a false chair on the table, or a true chair's object grown over the table, is."""
    truth = [GroundTruthObject(0, "table", Pose2(0.0, 0.0, 0.0), _rect(0.0, 0.0, 1.6, 0.9), 0.0, 0.75, name="table"),
             GroundTruthObject(1, "chair", Pose2(0.0, 0.5, 0.0), _rect(0.0, 0.5, 0.44, 0.44), 0.0, 0.9, name="chair")]
    cases = {
        "true chair beside": ([TrackedObject(1, "chair", Pose2(0.0, 0.52, 0.0), 0.44, 0.44, presence=0.95,
                                             footprint=_rect(0.0, 0.52, 0.44, 0.44))], "lost"),
        "false chair on it": ([TrackedObject(1, "chair", Pose2(0.0, 0.52, 0.0), 0.44, 0.44, presence=0.95,
                                             footprint=_rect(0.0, 0.52, 0.44, 0.44)),
                               TrackedObject(2, "chair", Pose2(0.5, 0.0, 0.0), 0.44, 0.44, presence=0.95,
                                             footprint=_rect(0.5, 0.0, 0.44, 0.44))], "merged"),
        "chair grown over it": ([TrackedObject(1, "chair", Pose2(0.0, 0.3, 0.0), 1.6, 1.3, presence=0.95,
                                               footprint=_rect(0.0, 0.2, 1.6, 1.1))], "merged"),
    }
    for name, (tracked, cause) in cases.items():
        report = evaluate_objects(tracked, truth, presence_threshold=0.8)
        explain_misses(report, truth, tracked, None, presence_threshold=0.8)
        causes = {r["name"]: r["cause"] for r in report.rows if r["kind"] == "truth"}
        assert causes["chair"] == "tp" and causes["table"] == cause, name
    # the other way round: the table found, the chair under its top missed — the table covers the chair as the
    # true table does: no merge; a table object grown over the chair's place beyond the true top: a merge
    for fp, cause in ((_rect(0.0, 0.0, 1.6, 0.9), "lost"), (_rect(0.0, 0.25, 1.6, 1.4), "merged")):
        tracked = [TrackedObject(1, "table", Pose2(0.0, 0.0, 0.0), 1.6, 0.9, presence=0.95, footprint=fp)]
        report = evaluate_objects(tracked, truth, presence_threshold=0.8)
        explain_misses(report, truth, tracked, None, presence_threshold=0.8)
        causes = {r["name"]: r["cause"] for r in report.rows if r["kind"] == "truth"}
        assert causes["table"] == "tp" and causes["chair"] == cause


def test_a_box_of_another_class_does_not_count_as_a_detection():
    truth = [GroundTruthObject(0, "gnome", Pose2(2.0, 0.0, 0.0), _rect(2.0, 0.0, 0.3, 0.3), 0.0, 1.0)]
    log = ObservationLog(1)
    log.add_frame(np.zeros(3), truth, np.array([True]), [("person", 0.0, 320.0)], 277.0, 160.0, 320, _rect(2.0, 0.0, 0.3, 0.3))
    assert (log.in_view, log.detected, log.lidar) == ([1], [0], [0])


# ----------------------------------------------------------------------------------------------
# One short headless run on a zoo world
# ----------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_short_headless_run_on_a_zoo_world_explains_its_misses():
    from app.bench.objects import run_world
    from app.config import Config

    cfg = Config.load(None, ["detector.kind=oracle", "camera.async_render=false"])
    world = load_world(ZOO_DIR / "narrow_bedroom.yaml")
    rep = run_world(cfg, "tour", 14.0, world)
    assert rep["world"] == "narrow_bedroom" and rep["sim_time_s"] == pytest.approx(14.0, abs=0.2)
    assert rep["collisions"] == 0 and rep["frames_logged"] > 30
    assert rep["in_scene"] == len(world.objects)
    misses = [r for r in rep["rows"] if r["kind"] == "truth" and not r["matched"]]
    assert all(r["cause"] in MISS_CAUSES for r in misses)
    assert sum(rep["miss_causes"].values()) == rep["fn"] == len(misses)
    # 14 s into the tour the robot has faced the room's far end: it found something, and the door behind
    # its start (facing away from it) is not yet in view
    assert rep["tp"] >= 1
    door = next(r for r in rep["rows"] if r["kind"] == "truth" and r["class"] == "door")
    assert door["matched"] or door["cause"] == "never_in_view"


def test_run_jobs_writes_each_world_as_it_is_done(tmp_path: Path, monkeypatch):
    """The suite runner keeps the jobs' order and appends every finished world to the JSONL file
    (here with a world loader that fails, so no simulator is started)."""
    import json

    from app.bench import objects as bench
    from app.config import Config

    jobs = [{"name": "a", "file": str(tmp_path / "missing_a.yaml")}, {"name": "b", "file": str(tmp_path / "missing_b.yaml")}]
    out = bench.run_jobs(Config(), jobs, 1.0, workers=1, quiet=True, jsonl=tmp_path / "w.jsonl")
    assert [r["job"]["name"] for r in out] == ["a", "b"] and all("cannot read world file" in r["error"] for r in out)
    lines = [json.loads(line) for line in (tmp_path / "w.jsonl").read_text().splitlines()]
    assert [r["job"]["name"] for r in lines] == ["a", "b"]
    assert bench.summarize(out)["worlds_failed"] == 2
