"""Dataset viewpoints (app/training/viewpoints.py): close views stand under or beside an object."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="module")
def sim_rz(tmp_path_factory):
    from app.config import Config
    from app.sim_world import SimWorld
    from app.training.randomization import Randomizer
    from app.world.generator import random_world

    world = random_world(4242)
    with SimWorld(world, Config(), seed=1, renderer="tiny") as sim:
        yield sim, Randomizer(sim, np.random.default_rng(3), tmp_path_factory.mktemp("tex"), (0, 0))


def _distances_to_objects(sim, poses) -> np.ndarray:
    """Each pose's distance to the nearest object footprint (0 inside one)."""
    from shapely.geometry import Point, Polygon

    polys = [Polygon(o.footprint()) for o in sim.world.objects]
    return np.array([min(poly.distance(Point(p.x, p.y)) for poly in polys) for p in poses])


def _poses(sim, rz, close: float, n: int = 40, seed: int = 11):
    from app.training.viewpoints import sample_viewpoint

    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        pose = sample_viewpoint(sim, rz, rng, close_views=close)
        if pose is not None:
            out.append(pose)
    return out


def test_close_views_stand_within_an_object_or_at_most_0_3_m_from_it(sim_rz) -> None:
    sim, rz = sim_rz
    close = _distances_to_objects(sim, _poses(sim, rz, 1.0))
    usual = _distances_to_objects(sim, _poses(sim, rz, 0.0))
    assert close.max() <= 0.3 + 1e-6
    assert (usual > 0.3).mean() > 0.5  # without the option most views stand back from every object
    for p in _poses(sim, rz, 1.0, n=10):
        assert rz.free_for_camera(p.x, p.y)  # under a table's top is free, inside a sofa is not


def test_no_close_views_draws_the_recipe_before_the_option(sim_rz) -> None:
    """close_views=0 draws no extra random number: the datasets of earlier recipes render again the same."""
    from app.training.viewpoints import sample_viewpoint

    sim, rz = sim_rz
    a, b = np.random.default_rng(5), np.random.default_rng(5)
    for _ in range(20):
        pa, pb = sample_viewpoint(sim, rz, a), sample_viewpoint(sim, rz, b, close_views=0.0)
        assert (pa is None and pb is None) or (pa.x, pa.y, pa.yaw) == (pb.x, pb.y, pb.yaw)
    assert a.random() == b.random()
