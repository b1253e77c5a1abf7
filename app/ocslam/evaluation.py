"""Object-map evaluation against ground truth: the paper's results table (§4), counted automatically.

Matching: an object of the map (presence ≥ threshold) matches a true object of the same class when
its centre lies inside the true footprint or within ``match_radius_m`` (0.5 m) of the true centre;
each true object is matched at most once (a legged object is matched once), by an optimal
assignment on centre distance.

False positives by cause, in this order:

- ``legs``: the extra object lies inside (or within ``touch_m`` of) the footprint of a true object of
  its own class (a leg, or a second piece of the same object);
- ``corner``: it lies on a true object of another class or on an unclassified obstacle or wall
  (its class belongs to something else: the paper's corner problem);
- ``other``: anything else (a ghost in free space, a duplicate farther away).

Strict precision = TP / in_map; lenient precision = (TP + legs) / in_map (the paper's 81 %);
recall = TP / in_scene; F1 from strict precision and recall.

False negatives by cause (:func:`explain_misses`, :data:`MISS_CAUSES`), the first that applies, in the
pipeline's order: ``never_in_view`` (no camera pose of the run had it in the field of view, unoccluded,
within range: :func:`app.ocslam.visibility.in_view_matrix`), ``never_detected`` (in view, but no box of its class covered its
image columns), ``no_lidar_support`` (boxed, but never a LIDAR return on it inside such a box),
``merged`` (an unmatched shown object of another class lies on it, or a shown object that stands for another true
object covers 30 % of it, 15 % more than that true object does: a true chair pushed under a missing table's edge, a
found table over a missing chair pushed under it, are no merges),
``mislocated`` (an unmatched shown object of its class stands within twice the match radius),
``below_threshold`` (an object of its class is tracked there with presence below the threshold),
``lost`` (none of these: nothing of its class near it in the final map). The evidence per frame is
gathered by an :class:`ObservationLog` from ground truth on the evaluation's side only.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import shapely
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment
from shapely.geometry import Point

from app.ocslam.messages import GroundTruthObject, GroundTruthObstacle, TrackedObject
from app.ocslam.visibility import box_covers, footprint_polygon, image_columns, point_columns

#: The paper's published row (spec §7).
PAPER_ROW: dict[str, Any] = dict(
    in_scene=10,
    in_map=16,
    tp=10,
    fn=0,
    fp_legs=3,
    fp_corner=2,
    fp_other=1,
    precision_strict=0.62,
    precision_lenient=0.81,
    recall=1.0,
)


@dataclass
class ObjectReport:
    """The results table's row for one run, plus per-object rows."""

    in_scene: int = 0
    in_map: int = 0
    tp: int = 0
    fn: int = 0
    fp_legs: int = 0
    fp_corner: int = 0
    fp_other: int = 0
    precision_strict: float = 0.0
    precision_lenient: float = 0.0
    recall: float = 0.0
    f1: float = 0.0
    pos_err_mean_m: float = 0.0
    pos_err_max_m: float = 0.0
    rows: list[dict[str, Any]] = field(default_factory=list)

    @property
    def fp(self) -> int:
        return self.fp_legs + self.fp_corner + self.fp_other

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["fp"] = self.fp
        return d


def evaluate_objects(
    objects: Sequence[TrackedObject],
    truth: Sequence[GroundTruthObject],
    obstacles: Sequence[GroundTruthObstacle] = (),
    presence_threshold: float = 0.8,
    match_radius_m: float = 0.5,
    touch_m: float = 0.15,
) -> ObjectReport:
    """Count the paper's table for a final object map (all positions in one frame)."""
    shown = [o for o in objects if o.presence >= presence_threshold]
    rep = ObjectReport(in_scene=len(truth), in_map=len(shown))
    t_polys = [footprint_polygon(t.footprint) for t in truth]
    t_xy = np.array([[t.pose.x, t.pose.y] for t in truth]).reshape(-1, 2)
    o_xy = np.array([[o.pose.x, o.pose.y] for o in shown]).reshape(-1, 2)

    # candidate matches: same class, centre inside the true footprint or within the radius
    BIG = 1e6
    cost = np.full((len(shown), len(truth)), BIG)
    for i, o in enumerate(shown):
        for j, t in enumerate(truth):
            if o.label != t.label:
                continue
            d = float(np.hypot(*(o_xy[i] - t_xy[j])))
            tp = t_polys[j]
            inside = tp is not None and tp.covers(Point(o_xy[i]))
            if inside or d <= match_radius_m:
                cost[i, j] = d
    matched_obj: dict[int, int] = {}
    if len(shown) and len(truth):
        ri, cj = linear_sum_assignment(cost)
        for i, j in zip(ri, cj):
            if cost[i, j] < BIG:
                matched_obj[int(i)] = int(j)
    matched_truth = {j: i for i, j in matched_obj.items()}
    rep.tp = len(matched_obj)
    rep.fn = rep.in_scene - rep.tp

    errs = []
    for j, t in enumerate(truth):
        row: dict[str, Any] = {
            "kind": "truth",
            "class": t.label,
            "name": t.name,
            "true_xy": [round(float(t_xy[j, 0]), 3), round(float(t_xy[j, 1]), 3)],
            "matched": j in matched_truth,
        }
        if j in matched_truth:
            i = matched_truth[j]
            e = float(np.hypot(*(o_xy[i] - t_xy[j])))
            errs.append(e)
            row.update(
                est_xy=[round(float(o_xy[i, 0]), 3), round(float(o_xy[i, 1]), 3)],
                error_m=round(e, 3),
                object_id=shown[i].id,
                presence=round(float(shown[i].presence), 3),
                source=shown[i].source,
                cause="tp",
            )
        else:
            row.update(est_xy=None, error_m=None, cause="fn")
        rep.rows.append(row)

    obstacle_polys = [p for p in (footprint_polygon(o.footprint) for o in obstacles) if p is not None]
    obstacle_union = shapely.union_all(obstacle_polys) if obstacle_polys else None
    known_polys = [(j, tp) for j, tp in enumerate(t_polys) if tp is not None]
    for i, o in enumerate(shown):
        if i in matched_obj:
            continue
        pt = Point(o_xy[i])
        cause = "other"
        same = [j for j, tp in known_polys if truth[j].label == o.label and tp.distance(pt) <= touch_m]
        if same:
            cause = "legs"
        else:
            other = [j for j, tp in known_polys if truth[j].label != o.label and tp.distance(pt) <= touch_m]
            if other or (obstacle_union is not None and obstacle_union.distance(pt) <= touch_m):
                cause = "corner"
        if cause == "legs":
            rep.fp_legs += 1
        elif cause == "corner":
            rep.fp_corner += 1
        else:
            rep.fp_other += 1
        rep.rows.append(
            {
                "kind": "false_positive",
                "class": o.label,
                "name": "",
                "true_xy": None,
                "est_xy": [round(float(o_xy[i, 0]), 3), round(float(o_xy[i, 1]), 3)],
                "matched": False,
                "error_m": None,
                "object_id": o.id,
                "presence": round(float(o.presence), 3),
                "source": o.source,
                "cause": cause,
            }
        )

    if rep.in_map:
        rep.precision_strict = rep.tp / rep.in_map
        rep.precision_lenient = (rep.tp + rep.fp_legs) / rep.in_map
    else:
        rep.precision_strict = rep.precision_lenient = 1.0 if rep.in_scene == 0 else 0.0
    rep.recall = rep.tp / rep.in_scene if rep.in_scene else 1.0
    p, r = rep.precision_strict, rep.recall
    rep.f1 = 2 * p * r / (p + r) if p + r > 0 else 0.0
    if errs:
        rep.pos_err_mean_m = float(np.mean(errs))
        rep.pos_err_max_m = float(np.max(errs))
    return rep


_COLUMNS = (
    ("in_scene", "in scene", "d"),
    ("in_map", "in map", "d"),
    ("tp", "TP", "d"),
    ("fn", "FN", "d"),
    ("fp_legs", "FP legs", "d"),
    ("fp_corner", "FP corner", "d"),
    ("fp_other", "FP other", "d"),
    ("precision_strict", "prec. strict", "%"),
    ("precision_lenient", "prec. lenient", "%"),
    ("recall", "recall", "%"),
    ("f1", "F1", "f"),
    ("pos_err_mean_m", "err mean m", "f"),
    ("pos_err_max_m", "err max m", "f"),
)


def _cell(v: Any, kind: str) -> str:
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "–"
    if kind == "d":
        return str(int(v))
    if kind == "%":
        return f"{100.0 * float(v):.0f} %"
    return f"{float(v):.3f}"


def format_table(rows: Mapping[str, ObjectReport | Mapping[str, Any]]) -> str:
    """The paper's results table: one line per named row (``ObjectReport`` or a dict like ``PAPER_ROW``)."""
    header = ["run"] + [c[1] for c in _COLUMNS]
    body = []
    for name, r in rows.items():
        d = r.as_dict() if isinstance(r, ObjectReport) else dict(r)
        body.append([str(name)] + [_cell(d.get(key), kind) for key, _, kind in _COLUMNS])
    widths = [max(len(h), *(len(b[i]) for b in body)) if body else len(h) for i, h in enumerate(header)]
    lines = [" | ".join(h.ljust(w) if i == 0 else h.rjust(w) for i, (h, w) in enumerate(zip(header, widths)))]
    lines.append("-+-".join("-" * w for w in widths))
    for b in body:
        lines.append(" | ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(b, widths))))
    return "\n".join(lines)


# ----------------------------------------------------------------------------------------------
# Why was an object missed? (issue 9, item 5)
# ----------------------------------------------------------------------------------------------

#: causes of a false negative, in pipeline order (the first that applies is reported)
MISS_CAUSES: tuple[str, ...] = (
    "never_in_view",  # no camera pose of the run had it in the field of view, unoccluded, in range
    "never_detected",  # in view, but no box of its class covered its image columns
    "no_lidar_support",  # detected, but no LIDAR return on it inside any such box
    "merged",  # a shown object that stands for another true object, or is of another class, lies on it
    "mislocated",  # an unmatched object of its class is there, beyond the match radius of its centre
    "below_threshold",  # a tracked object of its class is there, with presence below the threshold
    "lost",  # seen, detected and supported, yet no tracked object of its class near it at the end
)


@dataclass
class ObservationLog:
    """Per true object, how often a run saw it, detected it and had LIDAR on it (the evidence behind
    :func:`explain_misses`). Filled frame by frame with :meth:`add_frame`; all in the map frame."""

    n: int
    in_view: NDArray[np.int64] = field(init=False)  # (n,) frames it was in the camera's view
    detected: NDArray[np.int64] = field(init=False)  # (n,) frames a box of its class covered it
    lidar: NDArray[np.int64] = field(init=False)  # (n,) frames such a box also held a LIDAR return on it
    frames: int = 0

    def __post_init__(self) -> None:
        self.in_view = np.zeros(self.n, dtype=np.int64)
        self.detected = np.zeros(self.n, dtype=np.int64)
        self.lidar = np.zeros(self.n, dtype=np.int64)

    def add_frame(
        self,
        T_map_camera: np.ndarray,
        truth: Sequence[GroundTruthObject],
        in_view: np.ndarray,
        boxes: Sequence[tuple[str, float, float]],
        fx: float,
        cx: float,
        width: int,
        scan_points_map: np.ndarray | None = None,
        support_m: float = 0.06,
    ) -> None:
        """One camera frame: ``in_view`` ``(N,)`` bool (a row of :func:`in_view_matrix`), ``boxes``
        ``[(class name, x1, x2)]`` in pixel columns, ``scan_points_map`` ``(M, 2)`` the synced scan's
        returns in the map frame (true pose). An object is *detected* when a box of its class covers
        its columns (:func:`box_covers`); it has *LIDAR support* when one of those boxes also holds a
        return within ``support_m`` of its footprint."""
        self.frames += 1
        iv = np.asarray(in_view, dtype=bool).reshape(-1)
        self.in_view += iv
        pts = np.zeros((0, 2)) if scan_points_map is None else np.asarray(scan_points_map, dtype=np.float64).reshape(-1, 2)
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        for j in np.flatnonzero(iv).tolist():
            t = truth[j]
            cols = image_columns(T_map_camera, t.footprint, fx, cx, width)
            hit = [(x1, x2) for lab, x1, x2 in boxes if lab == t.label and box_covers(cols, x1, x2)]
            if not hit:
                continue
            self.detected[j] += 1
            poly = footprint_polygon(t.footprint)
            if poly is None or not len(pts):
                continue
            near = shapely.dwithin(poly, shapely.points(pts), support_m)
            if not near.any():
                continue
            u = point_columns(T_map_camera, pts[near], fx, cx)
            if any(((u >= x1) & (u <= x2)).any() for x1, x2 in hit):
                self.lidar[j] += 1


def explain_misses(
    report: ObjectReport,
    truth: Sequence[GroundTruthObject],
    tracked: Sequence[TrackedObject],
    log: ObservationLog | None,
    presence_threshold: float = 0.8,
    match_radius_m: float = 0.5,
    touch_m: float = 0.15,
) -> dict[str, int]:
    """Give every false negative of ``report`` a cause (:data:`MISS_CAUSES`), in place: each missed
    truth row gets ``cause`` and ``miss_detail``. ``tracked`` is the whole object map, below-threshold
    objects included; ``log`` the run's :class:`ObservationLog` (``None``: only the map-side causes
    ``merged``/``below_threshold``/``lost`` can be told apart). Returns the count per cause."""
    counts = {c: 0 for c in MISS_CAUSES}
    truth_rows = [r for r in report.rows if r.get("kind") == "truth"]
    shown_ids = {o.id for o in tracked if o.presence >= presence_threshold}
    owner: dict[int, str] = {}  # object id → what it stands for (matched truth name or "false positive")
    for r in report.rows:
        if r.get("object_id") is not None:
            owner[int(r["object_id"])] = str(r.get("name") or r.get("class")) if r.get("kind") == "truth" else f"a false {r.get('class')}"
    stands_for: dict[int, int] = {}  # shown object id → the index of the true object it was matched to
    for k, r in enumerate(truth_rows):
        if r.get("matched") and r.get("object_id") is not None:
            stands_for[int(r["object_id"])] = k
    truth_polys = [footprint_polygon(t.footprint) for t in truth]
    shown = [(o, footprint_polygon(o.footprint) if o.footprint is not None else None) for o in tracked if o.id in shown_ids]
    for j, (t, row) in enumerate(zip(truth, truth_rows)):
        if row.get("matched"):
            continue
        poly = truth_polys[j]
        txy = np.array([t.pose.x, t.pose.y])
        cause, detail = "lost", ""
        if log is not None and log.in_view[j] == 0:
            cause = "never_in_view"
        elif log is not None and log.detected[j] == 0:
            cause, detail = "never_detected", f"in view in {int(log.in_view[j])} frames"
        elif log is not None and log.lidar[j] == 0:
            cause, detail = "no_lidar_support", f"detected in {int(log.detected[j])} frames"
        else:
            on_it, covers = [], set()
            for o, ofp in shown:
                near = poly is not None and poly.distance(Point(o.pose.x, o.pose.y)) <= touch_m
                if ofp is not None and poly is not None and poly.area > 0:
                    over = ofp.intersection(poly).area
                    if over >= 0.3 * poly.area:
                        # an object standing for another true object covers this one beyond what that object
                        # does (a table's true top covers the chair pushed under it: no merge)
                        own_k = stands_for.get(o.id)
                        own = truth_polys[own_k] if own_k is not None else None
                        if over - (own.intersection(poly).area if own is not None else 0.0) >= 0.15 * poly.area:
                            covers.add(o.id)
                if near or o.id in covers:
                    on_it.append(o)
            same = [o for o in tracked if o.label == t.label and o.id not in shown_ids and (
                float(np.hypot(o.pose.x - txy[0], o.pose.y - txy[1])) <= match_radius_m
                or (poly is not None and poly.covers(Point(o.pose.x, o.pose.y))))]
            # an object that stands for another true object took this one only if it covers it: a true chair
            # pushed under a missing table's top stands beside it, not for it
            merged = [o for o in on_it if (o.id in covers if o.id in stands_for else o.label != t.label)]
            astray = [o for o in tracked if o.id in shown_ids and o.label == t.label and o.id not in stands_for
                      and float(np.hypot(o.pose.x - txy[0], o.pose.y - txy[1])) <= 2 * match_radius_m]
            def dist(o: TrackedObject, txy: np.ndarray = txy) -> float:
                return float(np.hypot(o.pose.x - txy[0], o.pose.y - txy[1]))

            if merged:
                o = min(merged, key=dist)
                cause, detail = "merged", f"into {o.label} #{o.id} ({owner.get(o.id, 'unmatched')})"
            elif astray:
                o = min(astray, key=dist)
                cause, detail = "mislocated", f"{o.label} #{o.id} {dist(o):.2f} m from its centre"
            elif same:
                o = max(same, key=lambda o: o.presence)
                cause, detail = "below_threshold", (f"{o.label} #{o.id} at presence {o.presence:.2f} ({o.frames_seen} "
                                                      f"counted frames, box confidence {o.detection_confidence:.2f})")
        counts[cause] += 1
        row["cause"] = cause
        row["miss_detail"] = detail
    return counts
