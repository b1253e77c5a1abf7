"""Islands and scan clusters: the numpy union-find agrees with scipy's connected components."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from app.ocslam.islands import close_pairs, cluster_extents, components, islands_linkage


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 60), st.lists(st.tuples(st.integers(0, 59), st.integers(0, 59)), max_size=120))
def test_components_equal_scipys_labels(n: int, edges: list[tuple[int, int]]) -> None:
    e = np.array([(a % n, b % n) for a, b in edges], dtype=np.int64).reshape(-1, 2)
    graph = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    c_ref, lab_ref = connected_components(graph, directed=False)
    c, lab = components(n, e[:, 0], e[:, 1])
    assert c == c_ref
    np.testing.assert_array_equal(lab, lab_ref)


def test_components_of_a_long_chain_and_no_edges() -> None:
    idx = np.arange(499)
    c, lab = components(500, idx[::-1], idx[::-1] + 1)  # a chain listed from its far end
    assert c == 1 and not lab.any()
    c, lab = components(4, np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))
    assert c == 4 and lab.tolist() == [0, 1, 2, 3]


def test_islands_split_at_gaps_larger_than_the_threshold() -> None:
    x = np.array([0.0, 0.05, 0.10, 0.30, 0.35, 1.0])
    pts = np.stack([x, np.zeros_like(x)], axis=1)
    isl = islands_linkage(pts, np.arange(6) + 10, 0.1)
    assert [i.indices.tolist() for i in isl] == [[10, 11, 12], [13, 14], [15]]
    labels, ext = cluster_extents(pts, 0.1)
    assert labels.tolist() == [0, 0, 0, 1, 1, 2]
    np.testing.assert_allclose(ext, [0.10, 0.05, 0.0], atol=1e-12)


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(2, 80), st.floats(0.02, 0.3))
def test_islands_from_the_scans_pairs_equal_islands_from_their_own_tree(seed: int, n: int, gap: float) -> None:
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-1.0, 1.0, (n, 2))
    idx = np.sort(rng.choice(n, size=int(rng.integers(1, n + 1)), replace=False))
    own = islands_linkage(pts[idx], idx, gap)
    shared = islands_linkage(pts[idx], idx, gap, close_pairs(pts, gap))
    assert [i.indices.tolist() for i in own] == [i.indices.tolist() for i in shared]
    labels, ext = cluster_extents(pts, gap)
    labels2, ext2 = cluster_extents(pts, gap, pairs_within_gap=close_pairs(pts, gap))
    np.testing.assert_array_equal(labels, labels2)
    np.testing.assert_array_equal(ext, ext2)
