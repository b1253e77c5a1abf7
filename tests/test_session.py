"""Sessions: save → load gives the same map, pose graph and objects, and mapping continues."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.config import ASSETS, Config
from app.pipeline import Pipeline
from app.session import SessionError, pack_state, save_session, summary_json, unpack_state, write_run_dir
from app.session_load import load_session

DETECTOR = "yolo" if (ASSETS / "models" / "detector.onnx").is_file() else "oracle"


def test_state_packing_round_trip() -> None:
    d = {"a": np.arange(3), "b": {"c": 1.5, "d": [{"x": np.eye(2)}, {"x": np.zeros(1)}], "e": []}, "s": "text",
         "m": {"k": [1, "two"]}, "n": np.float64(2.5)}
    back = unpack_state(pack_state(d))
    assert back["n"] == 2.5
    np.testing.assert_array_equal(back["a"], d["a"])
    assert back["b"]["c"] == 1.5 and back["s"] == "text" and back["b"]["e"] == []
    np.testing.assert_array_equal(back["b"]["d"][0]["x"], np.eye(2))
    assert back["m"]["k"] == [1, "two"]


@pytest.mark.slow
def test_save_load_round_trip_same_map_and_objects(tmp_path) -> None:
    cfg = Config.load(None, [f"detector.kind={DETECTOR}"])
    a = Pipeline(cfg)
    try:
        a.follow_route("tour")
        a.run_for(40.0)
        out = save_session(a, tmp_path / "s")
        grid_a = a.slam.occupancy_grid()
        objs_a = sorted((o.label, round(o.pose.x, 6), round(o.pose.y, 6), round(o.presence, 6)) for o in a.consciousness.objects)
        graph_a = a.slam.pose_graph()
        true_a = a.sim.true_pose()
    finally:
        a.close()
    for name in ("config.yaml", "summary.json", "map.yaml", "map.pgm", "objects.json", "trajectory_slam.tum",
                 "state.npz", "scene.viser", "scene.html"):
        assert (out / name).is_file(), name
    doc = json.loads((out / "objects.json").read_text())
    for det in doc["detections"]:  # vision_msgs/Detection3D field names
        assert {"header", "id", "results", "bbox"} <= set(det)
        assert {"class_id", "score"} == set(det["results"][0]["hypothesis"])
        assert set(det["bbox"]["size"]) == {"x", "y", "z"}
    b = Pipeline(Config.load(out / "config.yaml"))
    try:
        load_session(b, out)
        grid_b = b.slam.occupancy_grid()
        assert grid_b.resolution == grid_a.resolution and grid_b.origin == grid_a.origin
        np.testing.assert_array_equal(grid_b.data, grid_a.data)
        objs_b = sorted((o.label, round(o.pose.x, 6), round(o.pose.y, 6), round(o.presence, 6)) for o in b.consciousness.objects)
        assert objs_b == objs_a and len(objs_a) > 0
        graph_b = b.slam.pose_graph()
        np.testing.assert_allclose(graph_b.nodes, graph_a.nodes)
        assert b.sim.true_pose().distance(true_a) < 1e-9
        # mapping continues from there: the map grows, the pose stays consistent with the truth
        n0 = len(graph_b.nodes)
        b.follow_route("tour")
        b.run_for(15.0)
        assert len(b.slam.pose_graph().nodes) > n0
        err = b.T_map_base.distance(b.true_pose_map())
        assert err < 0.15, err
    finally:
        b.close()


def test_load_session_errors(tmp_path) -> None:
    cfg = Config.load(None, ["detector.kind=none"])
    p = Pipeline(cfg)
    try:
        with pytest.raises(SessionError, match="not a session directory"):
            load_session(p, tmp_path)
        (tmp_path / "state.npz").write_bytes(b"corrupt")
        with pytest.raises(SessionError, match="no config.yaml"):
            load_session(p, tmp_path)
        cfg.save(tmp_path / "config.yaml")
        with pytest.raises(SessionError, match="unreadable session state"):
            load_session(p, tmp_path)
        assert p.slam.occupancy_grid() is not None  # the running map is untouched
    finally:
        p.close()


def _files(d):
    return {f.name: f.read_bytes() for f in sorted(d.iterdir())}


def test_run_dir_is_replaced_as_a_unit(tmp_path) -> None:
    out = tmp_path / "run"

    def first(d):
        (d / "summary.json").write_text("{}")
        (d / "map.pgm").write_text("old map")

    def second(d):
        (d / "summary.json").write_text('{"new": 1}')

    assert write_run_dir(out, first) == out
    assert _files(out) == {"map.pgm": b"old map", "summary.json": b"{}"}
    write_run_dir(out, second)
    assert _files(out) == {"summary.json": b'{"new": 1}'}  # no stale map beside the new summary
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # no .prev, no temporary directory left
    mode = out.stat().st_mode & 0o777
    assert all((f.stat().st_mode & 0o777) == (mode & 0o666) for f in out.iterdir())


def test_a_failed_write_leaves_the_previous_run_directory(tmp_path) -> None:
    out = tmp_path / "run"
    write_run_dir(out, lambda d: (d / "summary.json").write_text("old"))
    before = _files(out)

    def broken(d):
        (d / "summary.json").write_text("half")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError, match="disk full"):
        write_run_dir(out, broken)
    assert _files(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_a_killed_write_is_cleaned_up_by_the_next(tmp_path) -> None:
    out = tmp_path / "run"
    stale = tmp_path / f".run.tmp-{2**22 + 12345}-abc"  # a pid that does not exist
    stale.mkdir()
    (stale / "state.npz").write_text("partial")
    write_run_dir(out, lambda d: (d / "summary.json").write_text("{}"))
    assert not stale.exists() and _files(out) == {"summary.json": b"{}"}


@pytest.mark.parametrize("setup, message", [
    (lambda p: p.write_text("x"), "is a file, not a directory"),
    (lambda p: (p.mkdir(), (p / "notes.txt").write_text("mine")), "is not a run directory"),
    (lambda p: (p.mkdir(), (p / "sub").mkdir(), (p / "summary.json").write_text("{}")), "is not a run directory"),
])
def test_what_is_not_a_run_directory_is_refused(tmp_path, setup, message) -> None:
    out = tmp_path / "out"
    setup(out)
    before = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*"))
    with pytest.raises(SessionError, match=message):
        write_run_dir(out, lambda d: (d / "summary.json").write_text("{}"))
    assert sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*")) == before


def test_summary_json_is_strict_json() -> None:
    text = summary_json({"a": float("nan"), "b": [1.0, float("inf")], "c": np.float64(2.5), "d": {"e": np.nan}})
    assert json.loads(text, parse_constant=lambda c: pytest.fail(f"bare {c}")) == {"a": None, "b": [1.0, None], "c": 2.5,
                                                                                      "d": {"e": None}}
