"""``ocslam sweep`` end to end on one short recording: the trace replays the full replay exactly, and a
4-trial sweep on local Ray gives the results table, a best config that loads, and resumes after an
interruption."""

from __future__ import annotations

import csv
import json
import pickle

import pytest

from app.config import Config
from app.ocslam.messages import Detection, Detections

pytest.importorskip("ray")

DURATION = 10.0  # sim seconds of the recording


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    from app.sweep.suite import record_world, suite_worlds

    folder = tmp_path_factory.mktemp("sweep") / "rec"
    w = suite_worlds("zoo-dev", ["meeting_room"])[0]
    meta = record_world(Config().to_dict(), w, folder, 0.2, DURATION)
    assert meta["sim_time_s"] == pytest.approx(DURATION, abs=0.05)
    return folder


def test_filter_detections_known_answer():
    from app.sweep.trace import filter_detections

    d = Detections(1.0, 64, 48, ())
    assert filter_detections(d, 0.5) is d
    mk = lambda conf: Detection(x1=0.0, y1=0.0, x2=10.0, y2=10.0, class_id=0, confidence=conf)  # noqa: E731
    d = Detections(1.0, 64, 48, (mk(0.9), mk(0.5), mk(0.3)))
    assert [b.confidence for b in filter_detections(d, 0.5).boxes] == [0.9, 0.5]
    assert filter_detections(d, 0.3) is d
    assert filter_detections(d, 0.95).boxes == ()


@pytest.mark.slow
def test_trace_reproduces_the_full_replay(recording):
    """The trace's consciousness-only replay gives the object map the full --reuse-detections replay gives."""
    from app.ros2.replay import ReplayCore
    from app.sweep.trace import build_trace, open_bag, replay_trace

    cfg = Config()
    cfg.set("detector.confidence", 0.2)
    cfg.set("replay.snapshot_period_s", 3600.0)
    tr = build_trace(recording / "bag", cfg, "mr", 0.2)
    assert tr.info["frames"] > 20
    core = ReplayCore(cfg, open_bag(recording / "bag", cfg), reuse_detections=True)
    core.run()
    full = sorted((o.label, o.pose.x, o.pose.y, o.presence) for o in core.objects_in_map())
    mine = sorted((o.label, o.pose.x, o.pose.y, o.presence) for o in replay_trace(tr, cfg))
    assert full and mine == full
    tr2 = pickle.loads(pickle.dumps(tr))  # what travels through Ray's object store
    assert sorted((o.label, o.pose.x, o.pose.y, o.presence) for o in replay_trace(tr2, cfg)) == full


@pytest.mark.slow
def test_four_trial_sweep_table_best_config_and_resume(recording, tmp_path):
    import ray

    from app.sweep.results import best_row, write_best, write_plots, write_table
    from app.sweep.spec import parse_spec
    from app.sweep.trace import score_trace
    from app.sweep.trial import trial_config
    from app.sweep.tune import RESULTS, read_results, run_sweep

    spec = parse_spec({"name": "t4", "suite": {"bags": [str(recording / "bag")]},
                       "params": {"consciousness.presence_threshold": {"range": [0.3, 0.9], "step": 0.05},
                                  "consciousness.frames_for_presence": [1, 2, 5],
                                  "detector.confidence": {"range": [0.2, 0.6], "step": 0.05}},
                       "trials": 4, "seed": 3, "include_defaults": True})
    out = tmp_path / "out"
    try:
        info = run_sweep(spec, out, workers=2, cache=tmp_path / "cache", stop_after=1, quiet=True)
        first = read_results(out / RESULTS)
        assert info["cluster"]["local"] and 1 <= len(first) < 4  # interrupted after the first trial
        info = run_sweep(spec, out, workers=2, cache=tmp_path / "cache", resume=True, quiet=True)
    finally:
        ray.shutdown()
    assert info["resumed"]
    rows = read_results(out / RESULTS)
    assert len(rows) == 4 and len({r["trial_id"] for r in rows}) == 4
    assert {r["trial_id"] for r in first} <= {r["trial_id"] for r in rows}
    assert any(r["params"] == spec.defaults() for r in rows)  # include_defaults: the base values are a trial
    # each trial's figures are what its configuration gives on the recording (recomputed here)
    with open(next((tmp_path / "cache").glob("bag-*/trace-*.pkl")), "rb") as f:
        tr = pickle.load(f)
    for r in rows:
        cfg = trial_config(spec.base_config().to_dict(), r["params"])
        assert r["per_world"]["rec"]["f1"] == pytest.approx(score_trace(tr, cfg)["f1"])
        assert r["mean_f1"] == pytest.approx(r["per_world"]["rec"]["f1"])
    csv_path, md_path = write_table(spec, rows, out)
    with open(csv_path, encoding="utf-8") as f:
        table = list(csv.DictReader(f))
    assert len(table) == 4 and {"consciousness.presence_threshold", "f1[rec]", "mean_f1", "objective"} <= set(table[0])
    assert md_path.read_text(encoding="utf-8").count("\n| ") == 5  # header + 4 trials
    best = best_row(rows)
    assert best["objective"] == max(r["objective"] for r in rows)
    y = write_best(spec, rows, out)
    loaded = Config.load(y)  # what `ocslam run --config` does
    for k, v in best["params"].items():
        assert loaded.get(k) == pytest.approx(v)
    plots = write_plots(spec, rows, out)
    assert {p.name for p in plots} >= {"precision_recall.png", "f1_vs_consciousness_frames_for_presence.png"}
    assert all(p.stat().st_size > 1000 for p in plots)
    assert json.loads((out / RESULTS).read_text().splitlines()[0])["trial_id"]


@pytest.mark.slow
def test_asha_stops_a_trial_that_finds_nothing_after_its_first_world(recording, tmp_path):
    """With ``scheduler: asha`` a trial reports after each world; one worse than the trials that reached the
    same world stops there (``complete`` false), and the best is chosen among the complete trials only."""
    import ray

    from app.sweep.results import best_row, write_table
    from app.sweep.spec import parse_spec
    from app.sweep.trace import score_trace
    from app.sweep.trial import trial_config
    from app.sweep.tune import RESULTS, read_results, run_sweep

    bags = []
    for name in ("w1", "w2", "w3"):  # three worlds of one recording (one cache entry, one trace)
        (tmp_path / name).symlink_to(recording, target_is_directory=True)
        bags.append(str(tmp_path / name / "bag"))
    # one worker, grid order: the 0.2 trial scores every world first; the 0.99 trial keeps no box (F1 0)
    # and is below the 0.2 trial's F1 after its first world: ASHA stops it there
    spec = parse_spec({"name": "asha", "suite": {"bags": bags}, "sampler": "grid",
                       "params": {"detector.confidence": [0.2, 0.99]},
                       "scheduler": {"asha": {"grace_worlds": 1, "reduction_factor": 2}}})
    out = tmp_path / "out"
    try:
        run_sweep(spec, out, workers=1, cache=tmp_path / "cache", quiet=True)
    finally:
        ray.shutdown()
    rows = {r["params"]["detector.confidence"]: r for r in read_results(out / RESULTS)}
    assert set(rows) == {0.2, 0.99}
    good, bad = rows[0.2], rows[0.99]
    with open(next((tmp_path / "cache").glob("bag-*/trace-*.pkl")), "rb") as f:
        tr = pickle.load(f)
    f1 = score_trace(tr, trial_config(spec.base_config().to_dict(), {"detector.confidence": 0.2}))["f1"]
    assert f1 > 0.0
    assert good["complete"] and good["worlds_done"] == 3 and set(good["per_world"]) == {"w1", "w2", "w3"}
    assert good["mean_f1"] == pytest.approx(f1)
    assert not bad["complete"] and bad["worlds_done"] == 1 and bad["mean_f1"] == 0.0
    assert best_row(list(rows.values()))["trial_id"] == good["trial_id"]
    _csv, md = write_table(spec, list(rows.values()), out)
    assert "1 stopped early by ASHA" in md.read_text(encoding="utf-8")


def test_a_recording_key_names_the_detector_models_content(tmp_path):
    """A retrained model at the same path is another recording (its boxes differ); the oracle's
    recordings do not depend on the model file."""
    from app.sweep.suite import World, recording_key

    model = tmp_path / "det.onnx"
    model.write_bytes(b"one model")
    w = World("w", seed=3, family="corridor")
    yolo = Config()
    yolo.set("detector.kind", "yolo")
    yolo.set("detector.model_path", str(model))
    k1 = recording_key(yolo.to_dict(), w, 0.2, 100.0)
    assert recording_key(yolo.to_dict(), w, 0.2, 100.0) == k1
    model.write_bytes(b"another model, retrained")
    k2 = recording_key(yolo.to_dict(), w, 0.2, 100.0)
    assert k2 != k1
    oracle = Config()
    oracle.set("detector.kind", "oracle")
    oracle.set("detector.model_path", str(model))
    k3 = recording_key(oracle.to_dict(), w, 0.2, 100.0)
    model.write_bytes(b"a third")
    assert recording_key(oracle.to_dict(), w, 0.2, 100.0) == k3


def test_a_recording_key_names_the_world_files_content_not_its_path(tmp_path):
    """An edited world (another route, a moved object) is another recording; the same content elsewhere
    (another checkout) is the same one."""
    from app.sweep.suite import World, recording_key

    cfg = Config()
    cfg.set("detector.kind", "oracle")
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir(), b.mkdir()
    text = "# a world\nname: w\n"
    (a / "w.yaml").write_text(text)
    (b / "w.yaml").write_text(text)
    k1 = recording_key(cfg.to_dict(), World("w", file=str(a / "w.yaml")), 0.2, 100.0)
    assert recording_key(cfg.to_dict(), World("w", file=str(b / "w.yaml")), 0.2, 100.0) == k1
    (a / "w.yaml").write_text(text + "routes: {tour: [[1.0, 0.0]]}\n")
    assert recording_key(cfg.to_dict(), World("w", file=str(a / "w.yaml")), 0.2, 100.0) != k1


def test_a_rosbag2_folder_is_named_by_its_content(tmp_path):
    """Two recordings in folders of the same name (``run1/bag``, ``run2/bag``) are two traces, never one;
    the same recording copied elsewhere is the same; a bag that is not there is named, not hashed."""
    from app.sweep.suite import content_sha256

    def bag(root, db: bytes):
        d = tmp_path / root / "bag"
        d.mkdir(parents=True)
        (d / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
        (d / "bag_0.mcap").write_bytes(db)
        return d

    a, b, c = bag("run1", b"one drive"), bag("run2", b"another drive"), bag("copy", b"one drive")
    ha = content_sha256(a)
    assert len(ha) == 64 and ha != content_sha256(b)
    assert content_sha256(c) == ha
    (c / "bag_1.mcap").write_bytes(b"")  # a second file is another recording
    assert content_sha256(c) != ha
    assert content_sha256(tmp_path / "nowhere" / "bag") == "missing-bag"


def test_a_recording_key_names_the_models_content_not_its_path(tmp_path):
    """The same model moved to another path (a candidate in runs/ copied into assets/) is the same recording."""
    from app.sweep.suite import World, recording_key

    a, b = tmp_path / "a.onnx", tmp_path / "b.onnx"
    a.write_bytes(b"the same weights")
    b.write_bytes(b"the same weights")
    w = World("w", seed=3, family="rooms")
    keys = []
    for m in (a, b):
        cfg = Config()
        cfg.set("detector.kind", "yolo")
        cfg.set("detector.model_path", str(m))
        keys.append(recording_key(cfg.to_dict(), w, 0.2, 100.0))
    assert keys[0] == keys[1]
