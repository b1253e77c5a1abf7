"""The camera renderer in the loop: chosen at start, reported in the summary and the metrics."""

from __future__ import annotations

import pytest

from app.config import Config
from app.pipeline import Pipeline
from app import sim_world


def _pipe(*over: str) -> Pipeline:
    return Pipeline(Config.load(None, ["detector.kind=none", "camera.async_render=false", "camera.render_width=160",
                                       *over]))


def test_forced_tiny_renderer_runs_and_is_reported():
    pipe = _pipe("sim.renderer=tiny")
    try:
        pipe.run_for(0.5)
        s = pipe.summary()
        assert s["renderer"] == "tiny" and "TinyRenderer" in s["renderer_note"]
        assert s["camera_size"] == [160, 120] and s["parallel_stages"] is True
        assert pipe.metrics()["renderer"] == "tiny"
        assert pipe.sim.render_camera(160, 120).image.data.shape == (120, 160, 3)
    finally:
        pipe.close()


def test_auto_falls_back_to_tiny_with_a_message_when_egl_fails(monkeypatch):
    monkeypatch.setenv(sim_world.EGL_PLUGIN_ENV, "/nonexistent/eglRenderer.so")
    monkeypatch.delenv(sim_world.EGL_PROBE_ENV, raising=False)
    pipe = _pipe("sim.renderer=auto")
    try:
        s = pipe.summary()
        assert s["renderer"] == "tiny" and "fallback" in s["renderer_note"]
    finally:
        pipe.close()


def test_auto_is_egl_where_it_loads():
    ok, why = sim_world.probe_egl()
    if not ok:
        pytest.skip(f"EGL cannot load here: {why}")
    pipe = _pipe("sim.renderer=auto")
    try:
        assert pipe.summary()["renderer"] == "egl"
        assert pipe.sim.render_camera(160, 120).image.data.std() > 0
    finally:
        pipe.close()


def test_the_renderer_environment_variable_chooses_for_auto(monkeypatch):
    monkeypatch.setenv(sim_world.RENDERER_ENV, "tiny")
    assert sim_world.resolve_renderer("auto")[0] == "tiny"
    assert sim_world.resolve_renderer("tiny")[0] == "tiny"
