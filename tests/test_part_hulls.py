"""Silhouettes drawn from a model's convex parts: known areas, the models that have none, the near plane."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.training.part_hulls import ModelHulls, model_hulls, raster_silhouette

K = np.array([[200.0, 0.0, 160.0], [0.0, 200.0, 120.0], [0.0, 0.0, 1.0]])


def _cube(side: float) -> ModelHulls:
    h = side / 2
    pts = np.array([[x, y, z] for x in (-h, h) for y in (-h, h) for z in (-h, h)], dtype=np.float64)
    return ModelHulls(pts, (0, 8))


def _ahead(distance: float) -> np.ndarray:
    """The model's origin ``distance`` m in front of the camera, its axes those of the optical frame."""
    T = np.eye(4)
    T[2, 3] = distance
    return T


def test_a_cube_face_on_fills_its_front_face() -> None:
    # a 1 m cube 3 m ahead: its front face at 2.5 m spans 200 · 1 / 2.5 = 80 px square, centred on the image
    mask = raster_silhouette(_cube(1.0), _ahead(3.0), K, (0, 0, 320, 240), 320, 240, near=0.05)
    assert mask is not None and mask.shape == (240, 320)
    rows, cols = np.nonzero(mask)
    assert abs(mask.sum() - 80 * 80) <= 4 * 81  # the fill differs from exact coverage by at most the outline
    assert 119 <= rows.min() + (rows.max() - rows.min()) / 2 <= 120 and 159 <= cols.min() + (cols.max() - cols.min()) / 2 <= 160


def test_a_coarser_grid_scales_the_area() -> None:
    full = raster_silhouette(_cube(1.0), _ahead(3.0), K, (100, 60, 220, 180), 120, 120, near=0.05)
    half = raster_silhouette(_cube(1.0), _ahead(3.0), K, (100, 60, 220, 180), 60, 60, near=0.05)
    assert full is not None and half is not None
    assert abs(half.sum() * 4 - full.sum()) <= 4 * 2 * 61  # within the coarse grid's outline


def test_a_point_behind_the_near_plane_leaves_it_to_the_renderer() -> None:
    assert raster_silhouette(_cube(1.0), _ahead(0.4), K, (0, 0, 320, 240), 64, 48, near=0.05) is None


@pytest.mark.parametrize("model", ["rubber_duck", "potted_flowers"])
def test_a_model_with_a_part_that_is_not_convex_has_no_hulls(model: str) -> None:
    assert model_hulls(model, 1.0) is None


@pytest.mark.parametrize("model", ["dining_chair", "dog", "soccer_ball", "door", "person", "table"])
def test_convex_models_have_one_hull_a_visible_part(model: str) -> None:
    from app.world.models.catalogue import get_model
    from app.world.models.parts import COLLISION_ONLY

    hulls = model_hulls(model, 1.0)
    assert hulls is not None
    assert len(hulls) == sum(p.role != COLLISION_ONLY for p in get_model(model).parts)
    assert hulls.points.shape[1] == 3 and hulls.starts[-1] == len(hulls.points)


def test_hulls_scale_with_the_model() -> None:
    a, b = model_hulls("round_table", 1.0), model_hulls("round_table", 1.2)
    assert a is not None and b is not None
    assert np.allclose(b.points, 1.2 * a.points)


def test_a_turned_model_turns_its_silhouette() -> None:
    """A dining chair seen from its side and from its front: different areas, each the same after a full turn."""
    hulls = model_hulls("dining_chair", 1.0)
    assert hulls is not None

    def seen(yaw: float) -> int:
        # camera 2 m in front of the chair, 0.5 m up, looking at it (optical frame: z forward, y down)
        R_cam_world = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])  # x forward in the world
        c, s = math.cos(yaw), math.sin(yaw)
        R_world_model = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        T = np.eye(4)
        T[:3, :3] = R_cam_world @ R_world_model
        T[:3, 3] = R_cam_world @ np.array([2.0, 0.0, -0.5])
        mask = raster_silhouette(hulls, T, K, (0, 0, 320, 240), 320, 240, near=0.05)
        assert mask is not None
        return int(mask.sum())

    front, side = seen(math.pi), seen(math.pi / 2)
    assert front != side
    assert seen(math.pi + 2 * math.pi) == front
