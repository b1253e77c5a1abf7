"""Headless frontier exploration on a small random world reaches ≥ 90 % coverage (issue 6)."""

from __future__ import annotations

import json

import pytest

from app.commands.run import run_headless
from app.config import Config
from app.world.format import dump_world
from app.world.generator import random_world


@pytest.mark.slow
def test_explore_a_small_random_world(tmp_path) -> None:
    world = random_world(7, n_rooms=3)
    path = tmp_path / "w.yaml"
    dump_world(world, path)
    cfg = Config.load(None, ["detector.kind=none", f"sim.world={path}"])
    rc = run_headless(cfg, explore=True, duration=900.0, out=tmp_path / "run", quiet=True)
    assert rc == 0
    s = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert s["exploration_complete"], s["end_reason"]
    assert s["coverage"] >= 0.90, s["coverage"]
    assert 0 < s["coverage_time_s"] <= s["sim_time_s"]
    assert s["collisions"] == 0
