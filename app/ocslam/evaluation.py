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
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np
import shapely
from scipy.optimize import linear_sum_assignment
from shapely.geometry import Point, Polygon

from app.ocslam.messages import GroundTruthObject, GroundTruthObstacle, TrackedObject

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


def _polygon(footprint: np.ndarray) -> Polygon | None:
    fp = np.asarray(footprint, dtype=np.float64).reshape(-1, 2)
    if len(fp) < 3 or not np.all(np.isfinite(fp)):
        return None
    poly = Polygon(fp)
    if not poly.is_valid:
        poly = poly.buffer(0)
    return poly if poly.area > 0 else None


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
    t_polys = [_polygon(t.footprint) for t in truth]
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
            inside = t_polys[j] is not None and t_polys[j].covers(Point(o_xy[i]))
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

    obstacle_polys = [p for p in (_polygon(o.footprint) for o in obstacles) if p is not None]
    obstacle_union = shapely.union_all(obstacle_polys) if obstacle_polys else None
    for i, o in enumerate(shown):
        if i in matched_obj:
            continue
        pt = Point(o_xy[i])
        cause = "other"
        same = [j for j, t in enumerate(truth) if t.label == o.label and t_polys[j] is not None and t_polys[j].distance(pt) <= touch_m]
        if same:
            cause = "legs"
        else:
            other = [j for j, t in enumerate(truth) if t.label != o.label and t_polys[j] is not None and t_polys[j].distance(pt) <= touch_m]
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
