"""The camera renderer in the loop: chosen at start, reported in the summary and the metrics."""

from __future__ import annotations

import threading

import pytest

from app import sim_world
from app.config import Config, resolve_path
from app.pipeline import Pipeline


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
    pipe = _pipe("sim.renderer=auto", "detector.kind=oracle")  # the loop renders the primary camera itself
    try:
        s = pipe.summary()
        assert s["renderer"] == "tiny" and "fallback" in s["renderer_note"]
    finally:
        pipe.close()


def test_auto_is_egl_where_it_loads():
    ok, why = sim_world.probe_egl()
    if not ok:
        pytest.skip(f"EGL cannot load here: {why}")
    pipe = _pipe("sim.renderer=auto", "detector.kind=oracle")
    try:
        assert pipe.summary()["renderer"] == "egl"
        assert pipe.summary()["renderer_note"].endswith("no shadow map")  # the render process's (sim.egl_shadow_map)
        assert pipe.sim.render_camera(160, 120).image.data.std() > 0
    finally:
        pipe.close()


def test_the_renderer_environment_variable_chooses_for_auto(monkeypatch):
    monkeypatch.setenv(sim_world.RENDERER_ENV, "tiny")
    assert sim_world.resolve_renderer("auto")[0] == "tiny"
    assert sim_world.resolve_renderer("tiny")[0] == "tiny"


def test_a_pipeline_stepped_on_another_thread_never_renders_with_egl():
    """The server builds a pipeline on one thread and steps it on its loop thread: an EGL context is
    current only where it was made (a render elsewhere kills the process), so its simulator renders with
    TinyRenderer; previews without a detector do too."""
    for over, same_thread in ((("detector.kind=oracle",), False), ((), True)):
        pipe = Pipeline(Config.load(None, ["detector.kind=none", "camera.async_render=false",
                                           "camera.render_width=160", "sim.renderer=auto", *over]),
                        same_thread=same_thread)
        try:
            assert pipe.sim.renderer == "tiny"
            out = []
            t = threading.Thread(target=lambda out=out, pipe=pipe: out.append(pipe.sim.render_camera(80, 60).image.data.shape))
            t.start()
            t.join()
            assert out == [(60, 80, 3)]
        finally:
            pipe.close()


def test_an_egl_world_refuses_renders_from_another_thread():
    ok, why = sim_world.probe_egl()
    if not ok:
        pytest.skip(f"EGL cannot load here: {why}")
    from app.world.format import load_world

    cfg = Config.load(None, ["camera.noise_std=0"])
    sim = sim_world.SimWorld(load_world(resolve_path("assets/worlds/small.yaml")), cfg, renderer="egl")
    try:
        errors: list[BaseException] = []

        def render() -> None:
            try:
                sim.render_camera(80, 60)
            except sim_world.RendererError as e:
                errors.append(e)

        t = threading.Thread(target=render)
        t.start()
        t.join()
        assert len(errors) == 1 and "thread" in str(errors[0])
        assert sim.render_camera(80, 60).image.data.std() > 0  # its own thread still renders
    finally:
        sim.close()
