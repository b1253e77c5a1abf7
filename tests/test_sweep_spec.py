"""``ocslam sweep``'s spec validation: clear one-line errors naming the key; the grid; the objective."""

from __future__ import annotations

import math
import re

import pytest
import yaml

from app.cli import main
from app.sweep.spec import Objective, SpecError, load_spec, parse_spec

OK = {"name": "t", "suite": "zoo-dev", "params": {"consciousness.presence_threshold": {"range": [0.5, 0.9]}}}


def spec(**kw):
    d = {**OK, **kw}
    return parse_spec({k: v for k, v in d.items() if v is not None})


def err(**kw) -> str:
    with pytest.raises(SpecError) as e:
        spec(**kw)
    msg = str(e.value)
    assert "\n" not in msg
    return msg


def test_valid_spec_parses():
    s = spec(params={"consciousness.frames_for_presence": [2, 5, 8], "detector.confidence": {"range": [0.2, 0.6], "step": 0.1},
                     "consciousness.tracking_threshold_m": {"range": [0.1, 0.6], "log": True}})
    assert [p.path for p in s.params] == ["consciousness.frames_for_presence", "detector.confidence",
                                           "consciousness.tracking_threshold_m"]
    assert s.params[0].values == [2, 5, 8] and s.params[0].kind == "int"
    assert s.replayable
    assert s.floor() == pytest.approx(0.2)  # the lowest threshold asked for
    assert s.defaults()["consciousness.frames_for_presence"] == 5


def test_unknown_parameter():
    m = err(params={"consciousness.presence_treshold": {"range": [0.5, 0.9]}})
    assert "unknown parameter 'consciousness.presence_treshold'" in m and "consciousness.presence_threshold" in m
    assert "unknown config section 'consciousnes'" in err(params={"consciousnes.presence_threshold": [0.5]})
    assert "is not SECTION.KEY" in err(params={"presence_threshold": [0.5]})


def test_range_outside_the_config_bounds():
    m = err(params={"consciousness.presence_threshold": {"range": [0.5, 1.2]}})
    assert m == "params.consciousness.presence_threshold.range: [0.5, 1.2] is outside the field's bounds [0.0, 1.0]"
    assert "outside the field's bounds [1, 100]" in err(params={"consciousness.frames_for_presence": {"range": [0, 10]}})
    assert "low must be below high" in err(params={"consciousness.presence_threshold": {"range": [0.9, 0.5]}})
    # a listed value out of bounds: the config's own error
    assert "consciousness.presence_threshold" in err(params={"consciousness.presence_threshold": [0.5, 1.5]})


def test_empty_suite():
    assert "no worlds" in err(suite={"random": [10, 9]})
    assert "no worlds" in err(suite={"bags": []})
    assert "unknown suite 'zoo-devv'" in err(suite="zoo-devv")
    assert "not in the suite" in err(only=["no_such_world"])
    assert "does not exist" in err(suite={"bags": ["/nonexistent/bag"]})


def test_other_errors():
    assert "sampler" in err(sampler="bayes")
    assert "trials" in err(trials=0)
    assert "recall_floor" in err(objective={"metric": "precision_at_recall"})
    assert "unknown key 'trails'" in err(trails=3)
    assert "a range needs a numeric field" in err(params={"consciousness.mode": {"range": [0, 1]}})
    assert "grid sampler needs a step" in err(sampler="grid")
    assert "set.detector.confidence" in err(set={"detector.confidence": 5.0})
    assert "never recorded" in err(record_floor=0.5)  # the base's threshold (0.4) is below it
    assert spec(record_floor=0.2).floor() == 0.2


def test_grid_values():
    s = spec(sampler="grid", params={"consciousness.presence_threshold": {"range": [0.5, 0.8], "step": 0.1},
                                     "consciousness.frames_for_presence": {"range": [2, 6], "step": 2}})
    assert s.params[0].grid_values() == pytest.approx([0.5, 0.6, 0.7, 0.8])
    assert s.params[1].grid_values() == [2, 4, 6]


def test_objective():
    assert Objective("f1").value({"f1": 0.7, "recall": 0.5, "precision_strict": 0.9}) == 0.7
    o = Objective("precision_at_recall", 0.6)
    assert o.value({"f1": 0.7, "recall": 0.65, "precision_strict": 0.9}) == 0.9
    assert math.isclose(o.value({"f1": 0.7, "recall": 0.5, "precision_strict": 1.0}), -0.1)  # below the floor: ranks by recall


def test_cli_prints_one_line(tmp_path, capsys):
    p = tmp_path / "s.yaml"
    p.write_text(yaml.safe_dump({**OK, "params": {"consciousness.presence_threshold": {"range": [0.5, 1.2]}}}))
    assert main(["sweep", str(p), "--check"]) == 2
    e = capsys.readouterr().err.strip().splitlines()
    assert len(e) == 1 and e[0].startswith("ocslam sweep: error: params.consciousness.presence_threshold.range")
    p.write_text(":\n- [")
    with pytest.raises(SpecError, match="not valid YAML"):
        load_spec(p)


def test_example_spec_is_valid():
    from app.config import PROJECT_ROOT

    s = load_spec(PROJECT_ROOT / "assets" / "sweeps" / "six-constants.yaml")
    assert len(s.params) == 6 and s.replayable and s.trials == 200
    for f in (PROJECT_ROOT / "assets" / "sweeps").glob("*.yaml"):  # every example the docs cite
        load_spec(f)
    a = load_spec(PROJECT_ROOT / "assets" / "sweeps" / "six-constants-asha.yaml")
    assert (a.scheduler.kind, a.params, a.trials, a.seed) == ("asha", s.params, s.trials, s.seed)


def test_oat_points_vary_one_parameter_at_a_time():
    s = spec(sampler="oat", params={"consciousness.presence_threshold": [0.6, 0.8, 0.9],
                                    "consciousness.frames_for_presence": [3, 5, 8]})
    pts = s.oat_points()
    d = {"consciousness.presence_threshold": 0.8, "consciousness.frames_for_presence": 5}
    assert pts[0] == d and len(pts) == 5  # the base point once, then 2 + 2 changes
    assert all(sum(p[k] != d[k] for k in d) == 1 for p in pts[1:])
    from app.sweep.tune import total_trials

    assert total_trials(s) == 5


def test_scheduler():
    from app.sweep.spec import Scheduler

    base = {"suite": "zoo-dev", "params": {"consciousness.presence_threshold": {"range": [0.5, 0.9]}}}
    assert parse_spec(base).scheduler == Scheduler("fifo")
    assert parse_spec({**base, "scheduler": "asha"}).scheduler == Scheduler("asha", 3, 4.0)
    s = parse_spec({**base, "scheduler": {"asha": {"grace_worlds": 2, "reduction_factor": 4}}}).scheduler
    assert (s.kind, s.grace_worlds, s.reduction_factor) == ("asha", 2, 4.0)
    one = {**base, "only": ["meeting_room"]}
    from app.bench.objects import zoo_split

    n_dev = len(zoo_split()["dev"])  # the zoo's dev half grows (a new dev world per failed test world)
    for body, msg in [("hyperband", "scheduler: expected fifo, asha"),
                      ({"asha": {"grace": 2}}, "scheduler.asha: expected"),
                      ({"asha": {"grace_worlds": 0}}, "grace_worlds: expected a positive integer"),
                      ({"asha": {"reduction_factor": 1}}, "reduction_factor: expected a number"),
                      ({"asha": {"grace_worlds": n_dev}}, f"is not below the suite's {n_dev} world(s)")]:
        with pytest.raises(SpecError, match=re.escape(msg)):
            parse_spec({**base, "scheduler": body})
    with pytest.raises(SpecError, match=re.escape("is not below the suite's 1 world(s)")):
        parse_spec({**one, "scheduler": "asha"})
