"""Ray casting invariants (hypothesis) and known answers."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from app.ocslam.slam.raycast import cast_scan, traverse

coord = st.floats(min_value=-20.0, max_value=20.0, allow_nan=False, allow_infinity=False)


def _segment_hits_cell(p0, p1, r, c, eps=1e-9):
    """Liang–Barsky: does the segment p0→p1 intersect the closed cell [c, c+1] × [r, r+1]?"""
    t0, t1 = 0.0, 1.0
    d = p1 - p0
    for pp, q in (
        (-d[0], p0[0] - c),
        (d[0], c + 1 - p0[0]),
        (-d[1], p0[1] - r),
        (d[1], r + 1 - p0[1]),
    ):
        if abs(pp) < 1e-15:
            if q < -eps:
                return False
        else:
            t = q / pp
            if pp < 0:
                t0 = max(t0, t)
            else:
                t1 = min(t1, t)
    return t0 <= t1 + eps


@settings(max_examples=200, deadline=None)
@given(coord, coord, coord, coord)
def test_hit_beam_invariants(x0, y0, x1, y1):
    p0, p1 = np.array([x0, y0]), np.array([x1, y1])
    fr, fc, hr, hc = cast_scan(p0, p1[None], np.array([True]))
    end = np.floor(p1).astype(int)
    # the end cell is occupied, and never free
    assert (hr[0], hc[0]) == (end[1], end[0])
    free = set(zip(fr.tolist(), fc.tolist()))
    assert (end[1], end[0]) not in free
    # every free cell is crossed by the segment
    for r, c in free:
        assert _segment_hits_cell(p0, p1, r, c)
    # every point strictly before the hit lies in a free cell or the end cell
    for f in np.linspace(0.0, 1.0, 97)[:-1]:
        q = p0 + f * (p1 - p0)
        if np.any(np.abs(q - np.round(q)) < 1e-7):
            continue  # exactly on a grid line: either side is right
        cell = (int(np.floor(q[1])), int(np.floor(q[0])))
        assert cell in free or cell == (end[1], end[0])


@settings(max_examples=100, deadline=None)
@given(coord, coord, coord, coord)
def test_no_return_beam_marks_nothing(x0, y0, x1, y1):
    p0, p1 = np.array([x0, y0]), np.array([x1, y1])
    fr, fc, hr, hc = cast_scan(p0, p1[None], np.array([False]))
    assert len(hr) == 0
    end = np.floor(p1).astype(int)
    assert (end[1], end[0]) in set(zip(fr.tolist(), fc.tolist()))  # cleared up to the limit


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(coord, coord, st.booleans()), min_size=1, max_size=20), coord, coord)
def test_hits_take_precedence(beams, x0, y0):
    ends = np.array([[b[0], b[1]] for b in beams])
    hit = np.array([b[2] for b in beams])
    fr, fc, hr, hc = cast_scan(np.array([x0, y0]), ends, hit)
    assert not (set(zip(fr.tolist(), fc.tolist())) & set(zip(hr.tolist(), hc.tolist())))
    assert len(hr) == hit.sum()


def test_known_answer_horizontal():
    b, r, c = traverse(np.array([0.5, 0.5]), np.array([[3.5, 0.5]]))
    assert sorted(zip(r.tolist(), c.tolist())) == [(0, 0), (0, 1), (0, 2), (0, 3)]
    fr, fc, hr, hc = cast_scan(np.array([0.5, 0.5]), np.array([[3.5, 0.5]]), np.array([True]))
    assert sorted(zip(fr.tolist(), fc.tolist())) == [(0, 0), (0, 1), (0, 2)]
    assert (hr.tolist(), hc.tolist()) == ([0], [3])


def test_known_answer_diagonal():
    # from (0.5, 0.2) to (2.5, 1.8): crosses x=1 at y=0.6, y=1 at x=1.5, x=2 at y=1.4
    b, r, c = traverse(np.array([0.5, 0.2]), np.array([[2.5, 1.8]]))
    assert sorted(zip(r.tolist(), c.tolist())) == [(0, 0), (0, 1), (1, 1), (1, 2)]
