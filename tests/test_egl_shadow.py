"""The EGL plugin's shadow-map pass (``sim.egl_shadow_map``, app/sim/egl_shadow.py)."""

from __future__ import annotations

import _ctypes

import numpy as np
import pytest

from app.ocslam.se2 import Pose2
from app.sim.egl_shadow import SHADOW_FLAG_SYMBOL, elf_symbol, shadow_map_switch
from app.sim.renderer import egl_plugin_path
from app.sim_world import SimWorld, probe_egl
from app.world.types import WorldObject
from tests.test_sim_world import box_room, quiet_config


def test_the_flag_is_only_looked_for_where_it_can_be_found(tmp_path):
    not_elf = tmp_path / "plugin.so"
    not_elf.write_text("not a shared object")
    assert elf_symbol(str(not_elf), SHADOW_FLAG_SYMBOL) is None
    assert elf_symbol(str(tmp_path / "missing.so"), SHADOW_FLAG_SYMBOL) is None
    assert elf_symbol(_ctypes.__file__, SHADOW_FLAG_SYMBOL) is None  # an ELF object without the flag
    switch, why = shadow_map_switch(None)
    assert switch is None and why == "no EGL plugin"
    switch, why = shadow_map_switch(_ctypes.__file__)
    assert switch is None and f"no one-byte {SHADOW_FLAG_SYMBOL}" in why


def test_the_plugin_names_its_shadow_flag():
    path = egl_plugin_path()
    if path is None:
        pytest.skip("pybullet has no eglRenderer plugin")
    sym = elf_symbol(path, SHADOW_FLAG_SYMBOL)
    assert sym is not None and sym[0] > 0 and sym[1] == 1
    switch, why = shadow_map_switch(path)  # the plugin is not loaded in this process until an EGL world exists
    assert switch is not None or why == "the plugin is not loaded in this process"


def test_without_the_shadow_map_the_frame_shows_the_same_objects_without_cast_shadows():
    """The switch really removes the pass (the images differ where the table casts its shadow), nothing
    else moves (segmentation identical), the default is off and the note says so; a camera that wants the
    pass gets it back at its next frame (the flag is per process)."""
    ok, why = probe_egl()
    if not ok:
        pytest.skip(f"EGL cannot load here: {why}")
    table = WorldObject(label="table", model="table", x=1.4, y=0.0, yaw=0.3)
    world = box_room(objects=[table])
    cfg = quiet_config(**{"camera.noise_std": 0.0})
    assert cfg.sim.egl_shadow_map is False
    with SimWorld(world, cfg, seed=0, renderer="egl") as sim:
        assert sim.renderer_note.endswith(", no shadow map")
        cam = sim._camera
        assert cam.shadow_switch is not None
        frames = {}
        for shadow in (True, False, True):
            cam.shadow_map = shadow
            frames[shadow] = sim.render_view(Pose2(0, 0, 0), width=160, height=120, segmentation=True)
            assert cam.shadow_switch.enabled is shadow
    a, b = frames[True], frames[False]
    assert np.array_equal(a.segmentation, b.segmentation)
    assert np.count_nonzero(a.segmentation == 0) > 200
    diff = np.abs(a.image.data.astype(int) - b.image.data.astype(int)).max(axis=2)
    assert np.count_nonzero(diff > 8) > 100, "the shadow-map pass made no difference: the switch did nothing"


def test_worlds_built_one_after_another_each_find_the_flag_where_the_plugin_is_now():
    """Closing the last EGL world unloads the plugin; the next load may map it elsewhere. Each world asks for
    the flag's address after its own load and a closed world forgets it (a stale address crashed the suite)."""
    ok, why = probe_egl()
    if not ok:
        pytest.skip(f"EGL cannot load here: {why}")
    cfg = quiet_config(**{"camera.noise_std": 0.0})
    for _ in range(3):
        sim = SimWorld(box_room(objects=[WorldObject(label="ball", model="soccer_ball", x=1.2, y=0.0, yaw=0.0)]), cfg,
                       seed=0, renderer="egl")
        cam = sim._camera
        assert cam.shadow_switch is not None
        for shadow in (True, False):
            cam.shadow_map = shadow
            assert sim.render_camera(64, 48).image.data.std() > 0
            assert cam.shadow_switch.enabled is shadow
        sim.close()
        assert cam.shadow_switch is None
