"""Collisions: the all-pairs shared-evidence test agrees with the KD-trees' distances."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from app.ocslam.collisions import shared_fractions
from app.ocslam.config import ConsciousnessConfig


def test_shared_fractions_equal_the_kd_trees_on_the_gap_too() -> None:
    cfg = ConsciousnessConfig()
    gap = max(0.5 * float(cfg.island_threshold_m), 0.03)
    rng = np.random.default_rng(3)
    for t in range(300):
        na, nb = (int(v) for v in rng.integers(0, 40, 2))
        if t % 2:  # voxel centres: pairs exactly a gap apart, where the rounding of a distance decides
            vs = float(rng.choice([0.01, 0.025, 0.05]))
            a = np.round(rng.uniform(-0.4, 0.4, (na, 2)) / vs) * vs
            b = np.round(rng.uniform(-0.4, 0.4, (nb, 2)) / vs) * vs
        else:
            a, b = rng.uniform(-0.4, 0.4, (na, 2)), rng.uniform(-0.4, 0.4, (nb, 2))
        want = (0.0, 0.0)
        if na and nb:
            da, _ = cKDTree(b).query(a, k=1)
            db, _ = cKDTree(a).query(b, k=1)
            want = (float(np.mean(da <= gap)), float(np.mean(db <= gap)))
        assert shared_fractions(a, b, cfg) == want
