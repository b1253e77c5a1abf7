"""The camera renderer in the loop: chosen at start, reported in the summary and the metrics."""

from __future__ import annotations

import math
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


@pytest.mark.parametrize("renderer", ["tiny", "egl"])
def test_a_world_built_in_a_lent_client_renders_as_in_its_own(renderer):
    """A dataset worker's RenderClient: world B after world A in one client gives the pixels and the
    segmentation B gives in a client of its own; the world's close leaves the lent client open."""
    from app.ocslam.se2 import Pose2
    from app.world.generator import random_world

    if renderer == "egl" and not sim_world.probe_egl()[0]:
        pytest.skip("EGL cannot load here")
    cfg = Config()
    a, b = random_world(5), random_world(6, family="corridor")

    def view(sim, pose):
        f = sim.render_view(pose, width=160, height=120, segmentation=True)
        return f.image.data.copy(), f.segmentation.copy()

    own = sim_world.SimWorld(b, cfg, seed=1, renderer=renderer)
    try:  # a view of world B along its tour that shows objects
        route = b.route("tour")
        poses = [Pose2(x0, y0, math.atan2(y1 - y0, x1 - x0)) for (x0, y0), (x1, y1) in zip(route[:-1], route[1:])]
        pose, want = next((q, v) for q in poses if ((v := view(own, q))[1] >= 0).sum() > 50)
    finally:
        own.close()
    client = sim_world.RenderClient(renderer)
    try:
        first = sim_world.SimWorld(a, cfg, seed=1, client=client)
        other = view(first, pose)
        first.close()
        assert client.id >= 0  # lent, not closed
        second = sim_world.SimWorld(b, cfg, seed=1, client=client)
        assert second.client == client.id and second.renderer == client.renderer == renderer
        got = view(second, pose)
        second.close()
    finally:
        client.close()
    assert not (got[0] == other[0]).all()  # world A's leftovers would show
    assert (got[0] == want[0]).all() and (got[1] == want[1]).all()
    assert client.id == -1
    with pytest.raises(RuntimeError, match="closed"):
        client.lend()


def test_a_render_client_asked_for_egl_that_cannot_load_it_says_so(monkeypatch):
    monkeypatch.setenv(sim_world.EGL_PLUGIN_ENV, "/nonexistent/eglRenderer.so")
    monkeypatch.delenv(sim_world.EGL_PROBE_ENV, raising=False)
    with pytest.raises(sim_world.RendererError, match="EGL"):
        sim_world.RenderClient("egl")
    fallback = sim_world.RenderClient("auto")
    try:
        assert fallback.renderer == "tiny" and "fallback" in fallback.note and fallback.gl_thread is None
    finally:
        fallback.close()
