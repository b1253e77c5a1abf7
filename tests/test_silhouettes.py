"""Silhouette areas measured coarse first: error bounds that hold, and label decisions those of fine renders."""

from __future__ import annotations

import numpy as np
import pytest

from app.training.labels import LabelFilter, make_labels, visible_boxes
from app.training.silhouettes import label_silhouettes

COARSE = 512  # coarser than the default, so that a coarse decision alone would go wrong in these views


class _Measured:
    """A renderer whose coarse measures (area, inside, ± area, ± inside) and fine areas are given."""

    def __init__(self, coarse: dict, fine: dict) -> None:
        self.coarse, self.fine, self.fine_asked = coarse, fine, []

    def measure(self, T, K, width, height, ids, *, max_pixels=None, raster_pixels=None):
        return {i: self.coarse[i] for i in ids}

    def silhouettes(self, T, K, width, height, ids, *, max_pixels=None):
        self.fine_asked += list(ids)
        return {i: self.fine[i] for i in ids}


def test_label_silhouettes_renders_finely_only_where_the_decision_is_in_doubt() -> None:
    filt = LabelFilter(min_pixels=30, min_visible_fraction=0.35, min_box_px=8, reference_width=320)
    boxes = {
        0: (10, 10, 60, 60, 1000),  # 1000 visible of ~1100: kept whatever the error
        1: (10, 10, 60, 60, 1000),  # 1000 of 2800 ± 200: the fraction 0.33–0.38 straddles 0.35
        2: (10, 10, 60, 60, 1000),  # 1000 of 9000 ± 300: dropped whatever the error
        3: (10, 10, 14, 60, 150),  # a 4-px-wide box: dropped by its width, whatever the areas
        4: (10, 10, 60, 60, 800),  # 800 of 2000 visible, 1000 ± 100 in the frame: the in-frame half in doubt
        5: (10, 10, 60, 60, 1000),  # rendered at the image's scale: exact, never again
    }
    coarse = {
        0: (1100, 1100, 60, 60),
        1: (2800, 2800, 200, 200),
        2: (9000, 9000, 300, 300),
        3: (2000, 2000, 500, 500),
        4: (2000, 1000, 0, 100),
        5: (2800, 2800, 0, 0),
    }
    fine = {1: (2700, 2700), 4: (2000, 1040)}
    r = _Measured(coarse, fine)
    got = label_silhouettes(r, np.eye(4), np.eye(3), 320, 240, boxes, filt)
    assert sorted(r.fine_asked) == [1, 4]
    assert got == {0: (1100, 1100), 1: (2700, 2700), 2: (9000, 9000), 3: (2000, 2000), 4: (2000, 1040), 5: (2800, 2800)}


@pytest.fixture(scope="module")
def views(tmp_path_factory):
    """30 rendered views of a generated world, with their classified candidates."""
    from app.config import Config
    from app.ocslam.messages import CLASS_INDEX
    from app.sim_world import SimWorld
    from app.training.randomization import Randomizer
    from app.training.viewpoints import sample_viewpoint
    from app.world.generator import random_world

    world = random_world(4242)
    rng = np.random.default_rng(7)
    out = []
    with SimWorld(world, Config(), seed=1, renderer="tiny") as sim:
        rz = Randomizer(sim, rng, tmp_path_factory.mktemp("tex"), (0, 0))
        while len(out) < 30:
            pose = sample_viewpoint(sim, rz, rng)
            if pose is None:
                continue
            frame = sim.render_view(pose, width=320, height=240, segmentation=True)
            vis = visible_boxes(frame.segmentation)
            cands = {i: v for i, v in vis.items() if 0 <= i < len(world.objects) and v[4] >= 30}
            if cands:
                out.append((frame, cands))
    class_of = {i: CLASS_INDEX[o.label] for i, o in enumerate(world.objects)}
    return world, class_of, out


class _CountingRenderer:
    """A :class:`SilhouetteRenderer` that counts the objects rendered finely."""

    def __init__(self, inner) -> None:
        self.inner, self.fine = inner, 0

    def measure(self, *a, **k):
        return self.inner.measure(*a, **k)

    def silhouettes(self, *a, **k):
        self.fine += len(a[4])
        return self.inner.silhouettes(*a, **k)


def _keeps(frame, cands, class_of, filt, areas) -> list[bool]:
    full = {k: v[0] for k, v in areas.items()}
    inside = {k: v[1] for k, v in areas.items()}
    return [lb.keep for lb in make_labels(frame.segmentation, class_of, full, filt, inside, boxes=cands)]


def test_coarse_error_bounds_hold_and_decisions_match_fine_renders(views) -> None:
    """On rendered views: the coarse areas' bounds hold the fine areas (all but sub-pixel features), the
    two-stage labels equal the fine ones, and most objects need no fine render."""
    from app.training.silhouettes import ModelClient, SilhouetteRenderer

    world, class_of, frames = views
    filt = LabelFilter()
    clients = ModelClient()
    held = total = 0
    try:
        with SilhouetteRenderer(world, clients=clients) as sil:
            counting = _CountingRenderer(sil)
            for frame, cands in frames:
                args = (frame.T_world_camera, frame.info.K, 320, 240)
                fine = sil.silhouettes(*args, list(cands))
                coarse = sil.measure(*args, list(cands), max_pixels=COARSE)
                for i, (a, ins, ea, ei) in coarse.items():
                    total += 1
                    held += abs(a - fine[i][0]) <= ea + 0.01 * fine[i][0] and abs(ins - fine[i][1]) <= ei + 0.01 * fine[i][1]
                two = label_silhouettes(counting, *args, cands, filt, coarse_pixels=COARSE)
                assert _keeps(frame, cands, class_of, filt, two) == _keeps(frame, cands, class_of, filt, fine)
    finally:
        clients.close()
    assert total > 40
    assert held >= 0.95 * total
    assert total - counting.fine >= 0.4 * total


def test_hull_fills_agree_with_fine_renders_within_their_bounds(views) -> None:
    """On rendered views: areas drawn from the models' convex parts (the first measure of ``label_silhouettes``)
    hold the fine renders' areas within their error bounds, and most objects are drawn, not rendered."""
    from app.training.part_hulls import model_hulls
    from app.training.silhouettes import ModelClient, SilhouetteRenderer

    world, class_of, frames = views
    clients = ModelClient()
    drawn = held = total = 0
    try:
        with SilhouetteRenderer(world, clients=clients) as sil:
            for frame, cands in frames:
                args = (frame.T_world_camera, frame.info.K, 320, 240)
                fine = sil.silhouettes(*args, list(cands))
                first = sil.measure(*args, list(cands), max_pixels=512, raster_pixels=16384)
                for i, (a, ins, ea, ei) in first.items():
                    o = world.objects[i]
                    c, s = np.cos(o.yaw), np.sin(o.yaw)
                    T_wo = np.array([[c, -s, 0, o.x], [s, c, 0, o.y], [0, 0, 1, 0], [0, 0, 0, 1.0]])
                    z = (np.linalg.solve(frame.T_world_camera, T_wo) @ clients.corners(o.model, o.scale).T)[2]
                    if model_hulls(o.model, o.scale) is None or z.min() <= sil.near:
                        continue  # rendered: a model that is not convex, or one reaching behind the near plane
                    drawn += 1
                    held += abs(a - fine[i][0]) <= ea and abs(ins - fine[i][1]) <= ei
                total += len(first)
    finally:
        clients.close()
    assert drawn >= 0.6 * total > 20
    assert held >= 0.97 * drawn
