"""Loop verification with the submap's free space: a place that only looks like an old one is rejected.

Scenario: two identical rooms (same size, same furniture), one open to a hall on its east side, the
other on its west side. Seen from inside, the walls and the furniture match perfectly; only what lies
beyond the openings differs. A keyframe in the second room whose drifted estimate puts it in the first
is offered a loop closure there by the correlative search; the free-space test rejects it. The same
keyframe taken in the first room is a true closure and passes.
"""

from __future__ import annotations

import math

import numpy as np

from app.ocslam.config import SlamConfig
from app.ocslam.se2 import Pose2, between, compose
from app.ocslam.slam.field import build_field
from app.ocslam.slam.freespace import build_free_space, contradiction, overlap_rival, overlap_scores
from app.ocslam.slam.keyframes import Keyframes, KeyframeScan
from app.ocslam.slam.loop import LoopCloser
from app.ocslam.slam.synthetic import box, simulate_scan

ROOM_W, ROOM_H = 6.0, 5.0
SHIFT = 20.0  # the twin room's offset along x


def _room(x0: float, open_side: str) -> list[list[float]]:
    """A 6 × 5 m room at ``x0`` with a 3 m opening in its east or west wall, a table and a cupboard."""
    x1, h = x0 + ROOM_W, ROOM_H
    segs = [[x0, 0.0, x1, 0.0], [x0, h, x1, h]]
    for x, side in ((x0, "west"), (x1, "east")):
        if side == open_side:
            segs += [[x, 0.0, x, 1.0], [x, 4.0, x, h]]
        else:
            segs += [[x, 0.0, x, h]]
    segs += box(x0 + 1.5, 1.0, x0 + 2.3, 1.6).tolist() + box(x0 + 4.0, 3.6, x0 + 4.6, 4.4).tolist()
    return segs


def world() -> np.ndarray:
    segs = _room(0.0, "east") + _room(SHIFT, "west")
    # the halls beyond the openings: a wall 4 m east of room A, 4 m west of room B, and far walls
    segs += [[10.0, -6.0, 10.0, 11.0], [SHIFT - 4.0, -6.0, SHIFT - 4.0, 11.0]]
    return np.array(segs, np.float64)


def _geometry(scan, max_range: float = 12.0) -> KeyframeScan:
    r = np.asarray(scan.ranges, np.float64)
    a = scan.angle_min + scan.angle_increment * np.arange(len(r))
    hit = np.isfinite(r) & (r < max_range)
    rr = np.where(hit, r, 3.0)
    ends = np.stack([rr * np.cos(a), rr * np.sin(a)], axis=1)
    return KeyframeScan(points=ends[hit], ends=ends, hit=hit, sensor=np.zeros(2))


def _scan(segs: np.ndarray, pose: np.ndarray, rng: np.random.Generator) -> KeyframeScan:
    sc = simulate_scan(Pose2(*pose), segs, n_beams=360, range_max=12.0, noise_std=0.005, rng=rng)
    return _geometry(sc)


def _cfg() -> SlamConfig:
    return SlamConfig(submap_keyframes=10, local_map_keyframes=5, loop_min_gap_keyframes=0, loop_query_keyframes=1,
                      loop_max_candidates=1, max_range_m=12.0)


def _keyframes(query_true: np.ndarray, query_est: np.ndarray) -> Keyframes:
    """15 keyframes inside room A (the submap), 10 far away (filler), then the query keyframe."""
    rng = np.random.default_rng(3)
    segs = world()
    kfs = Keyframes()
    t = 0.0
    for i in range(15):
        p = np.array([1.2 + 0.25 * i, 2.5 + 0.6 * math.sin(0.5 * i), 0.1 * i])
        kfs.add(t, p, _scan(segs, p, rng))
        t += 1.0
    for i in range(10):
        p = np.array([40.0 + 0.3 * i, 30.0, 0.0])
        kfs.add(t, p, _scan(segs, p, rng))
        t += 1.0
    kfs.add(t, query_est, _scan(segs, query_true, rng))
    return kfs


def _search(query_true, query_est):
    cfg = _cfg()
    kfs = _keyframes(np.asarray(query_true, float), np.asarray(query_est, float))
    lc = LoopCloser(cfg)
    return cfg, lc.search(kfs, len(kfs) - 1)


def test_twin_room_offers_a_closure_that_the_free_space_rejects():
    # the robot is in room B; its drifted estimate puts it in room A, 0.3 m and 3° off the alias
    true_b = np.array([SHIFT + 3.0, 2.2, 0.4])
    est = compose(true_b - np.array([SHIFT, 0.0, 0.0]), np.array([0.3, -0.2, math.radians(3.0)]))
    cfg, out = _search(true_b, est)
    assert len(out) == 1, "the twin room must look like room A to the correlative search"
    lc = out[0]
    # the closure found is the alias: room B's keyframe placed where the same view would be in room A
    alias = between(np.array([1.2, 2.5, 0.0]), true_b - np.array([SHIFT, 0.0, 0.0]))
    assert np.hypot(*(lc.measurement[:2] - alias[:2])) < 0.1
    assert lc.score >= cfg.loop_min_score
    assert lc.contradiction is not None
    assert lc.contradiction.worst > cfg.loop_max_contradiction, lc.contradiction


def test_the_same_view_in_the_first_room_is_a_true_closure_and_passes():
    true_a = np.array([3.0, 2.2, 0.4])
    est = compose(true_a, np.array([0.3, -0.2, math.radians(3.0)]))
    cfg, out = _search(true_a, est)
    assert len(out) == 1
    lc = out[0]
    truth = between(np.array([1.2, 2.5, 0.0]), true_a)
    assert np.hypot(*(lc.measurement[:2] - truth[:2])) < 0.05
    assert abs(lc.measurement[2] - truth[2]) < math.radians(0.5)
    assert lc.contradiction is not None
    assert lc.contradiction.worst < 0.5 * cfg.loop_max_contradiction, lc.contradiction
    assert lc.contradiction.points_judged > 100 and lc.contradiction.rays_judged > 100


def test_mapper_rejects_the_twin_with_reason_free_space():
    from app.ocslam.slam.mapper import Slam
    from app.ocslam.slam.verify import Candidate

    true_b = np.array([SHIFT + 3.0, 2.2, 0.4])
    est = compose(true_b - np.array([SHIFT, 0.0, 0.0]), np.array([0.3, -0.2, math.radians(3.0)]))
    cfg, out = _search(true_b, est)
    slam = Slam(cfg)
    # the same decision as Slam._add_keyframe makes for every closure the loop closer returns
    rejected = [lc for lc in out if lc.contradiction is not None and lc.contradiction.worst > cfg.loop_max_contradiction]
    for lc in rejected:
        slam.verifier.reject(Candidate(lc.anchor, lc.keyframe, lc.measurement, np.eye(3)), "free_space")
    assert slam.metrics()["slam_loops_rejected_by"] == {"free_space": 1}


def _corridor_points(x0: float, x1: float, step: float = 0.02) -> np.ndarray:
    x = np.arange(x0, x1, step)
    return np.vstack([np.stack([x, np.full_like(x, -1.0)], 1), np.stack([x, np.full_like(x, 1.0)], 1)])


def test_overlap_normalised_score_finds_the_slide_along_a_plain_corridor():
    # a submap that saw 8 m of a plain 2 m corridor; a query seeing 10 m of it, partly beyond the submap
    segs = np.array([[-20.0, -1.0, 30.0, -1.0], [-20.0, 1.0, 30.0, 1.0]])
    rng = np.random.default_rng(0)
    sub_poses = np.array([[0.25 * i, 0.0, 0.0] for i in range(16)])
    scans = [_scan(segs, p, rng) for p in sub_poses]
    for sc in scans:  # the submap's scanner saw 4 m ahead only
        keep = np.hypot(*sc.ends.T) < 4.0
        sc.points = sc.points[np.hypot(*sc.points.T) < 4.0]
        sc.ends, sc.hit = sc.ends[keep], sc.hit[keep]
    rel = sub_poses
    pts = np.vstack([transform(p, s.points) for p, s in zip(rel, scans)])
    fld = build_field(pts, 0.05, 0.07, margin_m=0.5)
    fs = build_free_space(rel, scans)
    assert fs is not None
    q = _scan(segs, np.array([2.0, 0.0, 0.0]), rng)
    query = q.points[np.hypot(*q.points.T) < 10.0]
    info = np.diag([1 / 0.05**2, 1 / 0.05**2, 1 / 0.02**2])
    true = np.array([2.0, 0.0, 0.0])
    # along the corridor every placement of the overlap fits equally well
    rival, s0, s1 = overlap_rival(fld, fs, query, true, info, 1.5, 1.0, 0.9, q)
    assert rival is not None and abs(rival[1]) < 0.05 and abs(rival[0] - 2.0) > 1.0
    assert s1 >= 0.9 * s0
    # across it (and with the corridor's end in view) nothing else fits
    sc_across, _ = overlap_scores(fld, fs, query, np.array([[2.0, 0.5, 0.0]]))
    assert sc_across[0] < 0.5 * s0
    # and the free-space test does not object to the true pose
    c = contradiction(fs, true, query, q.sensor, q.ends, q.hit)
    assert c.worst < 0.05, c


def test_overlap_rival_absent_where_the_overlap_has_structure():
    # the same corridor with a cross wall ahead, inside the submap's view: the axis is fixed
    segs = np.array([[-20.0, -1.0, 5.0, -1.0], [-20.0, 1.0, 5.0, 1.0], [5.0, -1.0, 5.0, 1.0]])
    rng = np.random.default_rng(1)
    sub_poses = np.array([[0.25 * i, 0.0, 0.0] for i in range(12)])
    scans = [_scan(segs, p, rng) for p in sub_poses]
    pts = np.vstack([transform(p, s.points) for p, s in zip(sub_poses, scans)])
    fld = build_field(pts, 0.05, 0.07, margin_m=0.5)
    fs = build_free_space(sub_poses, scans)
    assert fs is not None
    q = _scan(segs, np.array([1.0, 0.0, 0.0]), rng)
    info = np.diag([1 / 0.05**2, 1 / 0.05**2, 1 / 0.02**2])
    rival, s0, s1 = overlap_rival(fld, fs, q.points, np.array([1.0, 0.0, 0.0]), info, 1.5, 1.0, 0.9, q)
    assert rival is None, (rival, s0, s1)
    # without the query's beams the slide that hides the end wall behind the submap's would pass
    rival, s0, s1 = overlap_rival(fld, fs, q.points, np.array([1.0, 0.0, 0.0]), info, 1.5, 1.0, 0.9, None)
    assert rival is not None


def transform(pose: np.ndarray, pts: np.ndarray) -> np.ndarray:
    from app.ocslam.se2 import transform_points

    return transform_points(pose, pts)
