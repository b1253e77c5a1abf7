"""One trial: a configuration scored over the suite's worlds (no Ray here; :mod:`app.sweep.tune` calls it).

A *replay* trial (every swept field is a consciousness constant or ``detector.confidence``) runs the
consciousness on each world's :class:`~app.sweep.trace.Trace`; any other trial re-runs each world headless
(``ocslam bench objects``' :func:`~app.bench.objects.run_world`: simulator, detector, SLAM and all).
"""

from __future__ import annotations

import math
import time
from typing import Any

#: the figures averaged over the worlds (the paper's table's)
MEAN_KEYS = ("precision_strict", "recall", "f1", "pos_err_mean_m")


def clean(params: dict[str, Any]) -> dict[str, Any]:
    """A trial's values without the float noise of quantised sampling (``0.9500000000000001`` → ``0.95``)."""
    return {k: round(v, 10) if isinstance(v, float) else v for k, v in params.items()}


def trial_config(base: dict[str, Any], params: dict[str, Any]):
    """The base config with a trial's ``{"section.key": value}`` applied (validated)."""
    from app.config import Config

    cfg = Config.from_dict(base)
    for k, v in clean(params).items():
        cfg.set(k, v)
    return cfg


def mean_of(per_world: dict[str, dict[str, Any]]) -> dict[str, float]:
    out = {}
    for k in MEAN_KEYS:
        vals = [float(r[k]) for r in per_world.values() if r.get(k) is not None and math.isfinite(float(r[k]))]
        out[k] = sum(vals) / len(vals) if vals else math.nan
    return out


def score_replay(cfg, traces: dict[str, Any]) -> dict[str, dict[str, Any]]:
    from app.sweep.trace import score_trace

    per: dict[str, dict[str, Any]] = {}
    for name, tr in traces.items():
        t0 = time.perf_counter()
        per[name] = score_trace(tr, cfg)
        per[name]["wall_s"] = round(time.perf_counter() - t0, 3)
    return per


def score_headless(cfg, worlds: list[Any], duration: float) -> dict[str, dict[str, Any]]:
    from app.bench.objects import run_world
    from app.sweep.suite import load_world_of

    per: dict[str, dict[str, Any]] = {}
    for w in worlds:
        world = load_world_of(w)
        route = "tour" if "tour" in world.routes else next(iter(world.routes))
        rep = run_world(cfg, route, duration, world, explain=False)
        per[w.name] = {k: rep.get(k) for k in ("in_scene", "in_map", "tp", "fn", "fp", "precision_strict", "recall",
                                                "f1", "pos_err_mean_m", "wall_s")}
    return per
