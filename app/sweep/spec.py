"""The sweep file (``ocslam sweep SPEC.yaml``), validated against the config's own bounds.

.. code-block:: yaml

    name: six-constants                 # names the output folder runs/sweep-<name>
    suite: zoo-dev                      # zoo-dev | zoo-test | {random: [99000, 99009]} | {bags: [runs/a/bag]}
    only: [meeting_room]                # optional: a subset of the suite's worlds
    config: my.yaml                     # optional base config (else the defaults), then
    set: {detector.kind: yolo}          # optional overrides of the base
    params:                             # any config field, SECTION.KEY:
      consciousness.tracking_threshold_m: {range: [0.1, 0.6]}            # uniform (ints: integers)
      consciousness.presence_threshold: {range: [0.5, 0.95], step: 0.05} # quantised (grid: every step)
      consciousness.frames_for_presence: [2, 3, 5, 8]                    # a list of values
      detector.confidence: {range: [0.2, 0.6], log: false}
    sampler: random                     # grid | random | optuna (Tune's OptunaSearch, TPE) | oat (one at a
                                        # time: each parameter's grid with the others at the base values)
    objective: f1                       # f1 | {metric: precision_at_recall, recall_floor: 0.7}
    scheduler: fifo                     # fifo (every trial scores every world) | asha (Tune's ASHAScheduler:
                                        # a trial reports after each world, cheapest worlds first, and stops
                                        # early when its objective so far is not in the best 1/reduction_factor
                                        # of the trials that reached the same world) |
                                        # {asha: {grace_worlds: 3, reduction_factor: 4}}
    trials: 200                         # random/optuna: trials (grid: the grid's size)
    include_defaults: true              # random/optuna: the first trial is the base config's values
    record_floor: 0.2                   # optional: the detector threshold of the recordings (default: the
                                        # lowest any trial asks for); ≤ every trial's detector.confidence
    seed: 0
    duration: 1500                      # max sim seconds a world's route is driven (recordings, re-runs)

Every error is one line naming the key (:class:`SpecError`).
"""

from __future__ import annotations

import dataclasses
import difflib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

SAMPLERS = ("grid", "random", "optuna", "oat")
SCHEDULERS = ("fifo", "asha")
METRICS = ("f1", "precision_at_recall")
#: the fields a trial can change while replaying the recordings with the recorded boxes
REPLAYABLE_SECTIONS = ("consciousness",)
REPLAYABLE_FIELDS = ("detector.confidence", "detector.calibration")
#: the paper's six constants (docs/tuning.md)
SIX_CONSTANTS = ("consciousness.tracking_threshold_m", "consciousness.island_threshold_m",
                 "consciousness.presence_threshold", "consciousness.rolling_average_weight",
                 "detector.confidence", "consciousness.frames_for_presence")


class SpecError(ValueError):
    """A sweep file is invalid; the message is one line naming the offending key."""


@dataclass
class Param:
    """One swept field: ``values`` (a list) or ``low``/``high`` (+ ``step``, ``log``); ``kind`` int/float/other."""

    path: str
    kind: str
    values: list[Any] | None = None
    low: float | None = None
    high: float | None = None
    step: float | None = None
    log: bool = False

    def grid_values(self) -> list[Any]:
        if self.values is not None:
            return list(self.values)
        assert self.low is not None and self.high is not None
        if self.step is None:
            raise SpecError(f"params.{self.path}: the grid sampler needs a step (or a list of values)")
        n = int(math.floor((self.high - self.low) / self.step + 1e-9)) + 1
        vals = [self.low + i * self.step for i in range(n)]
        return [int(round(v)) for v in vals] if self.kind == "int" else [round(v, 10) for v in vals]


@dataclass
class Objective:
    metric: str = "f1"
    recall_floor: float = 0.0

    def value(self, mean: dict[str, float]) -> float:
        """The number maximised: the mean F1, or the mean strict precision if the mean recall reaches the
        floor (else the recall's shortfall below zero, so that trials still order towards the floor)."""
        if self.metric == "f1":
            return float(mean["f1"])
        r, p = float(mean["recall"]), float(mean["precision_strict"])
        return p if r >= self.recall_floor - 1e-12 else r - self.recall_floor

    def describe(self) -> str:
        return "mean F1" if self.metric == "f1" else f"mean strict precision at mean recall ≥ {self.recall_floor:g}"


@dataclass
class Scheduler:
    """When trials stop: ``fifo`` (every trial scores the whole suite) or ``asha`` (Tune's asynchronous
    successive halving: after ``grace_worlds`` worlds, then at every ``reduction_factor`` times as many, a
    trial goes on only if its objective so far is in the best ``1/reduction_factor`` of the trials that
    reached the same world)."""

    kind: str = "fifo"
    grace_worlds: int = 3
    reduction_factor: float = 4.0

    def describe(self) -> str:
        if self.kind == "fifo":
            return "every trial scores every world"
        return (f"ASHA: trials stop early after {self.grace_worlds} worlds (then ×{self.reduction_factor:g}) unless "
                f"in the best 1/{self.reduction_factor:g}")


def parse_scheduler(body: Any, n_worlds: int) -> Scheduler:
    """``fifo`` | ``asha`` | ``{asha: {grace_worlds: N, reduction_factor: R}}`` (one-line :class:`SpecError`)."""
    if body is None or body == "fifo":
        return Scheduler()
    if body == "asha":
        body = {"asha": {}}
    if not (isinstance(body, dict) and len(body) == 1 and next(iter(body)) in SCHEDULERS):
        raise SpecError(f"scheduler: expected fifo, asha or {{asha: {{grace_worlds: N, reduction_factor: R}}}}, got {body!r}")
    kind, opts = next(iter(body.items()))
    if kind == "fifo":
        return Scheduler()
    opts = opts or {}
    if not isinstance(opts, dict) or set(opts) - {"grace_worlds", "reduction_factor"}:
        raise SpecError(f"scheduler.asha: expected {{grace_worlds: N, reduction_factor: R}}, got {opts!r}")
    g = opts.get("grace_worlds", min(3, max(n_worlds - 1, 1)))
    if isinstance(g, bool) or not isinstance(g, int) or g < 1:
        raise SpecError(f"scheduler.asha.grace_worlds: expected a positive integer, got {g!r}")
    if g >= n_worlds:
        raise SpecError(f"scheduler.asha.grace_worlds: {g} is not below the suite's {n_worlds} world(s): "
                        "no trial could stop early (use fifo)")
    r = opts.get("reduction_factor", 4)  # Tune's default
    if isinstance(r, bool) or not isinstance(r, (int, float)) or not r >= 1.5:
        raise SpecError(f"scheduler.asha.reduction_factor: expected a number ≥ 1.5, got {r!r}")
    return Scheduler("asha", int(g), float(r))


@dataclass
class Spec:
    name: str
    suite: Any
    params: list[Param]
    only: list[str] = field(default_factory=list)
    config: str | None = None
    set: dict[str, Any] = field(default_factory=dict)
    sampler: str = "random"
    objective: Objective = field(default_factory=Objective)
    scheduler: Scheduler = field(default_factory=Scheduler)
    trials: int = 20
    seed: int = 0
    duration: float = 1500.0
    include_defaults: bool = True
    record_floor: float | None = None
    source: str = "spec"

    @property
    def replayable(self) -> bool:
        """True if every swept field can be evaluated on the recordings (``app.sweep.trace``)."""
        return all(p.path.split(".")[0] in REPLAYABLE_SECTIONS or p.path in REPLAYABLE_FIELDS for p in self.params)

    def base_config(self):
        """The config every trial starts from (``config`` file, then ``set``)."""
        from app.config import Config

        cfg = Config.load(self.config) if self.config else Config()
        for k, v in self.set.items():
            cfg.set(k, v)
        return cfg

    def defaults(self) -> dict[str, Any]:
        """The swept fields' values in the base config (the trial ``include_defaults`` adds)."""
        cfg = self.base_config()
        return {p.path: cfg.get(p.path) for p in self.params}

    def oat_points(self) -> list[dict[str, Any]]:
        """One-at-a-time sensitivity: the base values, then each parameter's grid values with the others at
        the base values (the base point once)."""
        d = self.defaults()
        pts = [dict(d)]
        for p in self.params:
            for v in p.grid_values():
                q = {**d, p.path: v}
                if q not in pts:
                    pts.append(q)
        return pts

    def floor(self) -> float:
        """The detector threshold recordings are made at: the lowest any trial asks for (and ≤ the base's)."""
        base = float(self.base_config().detector.confidence)
        if self.record_floor is not None:
            return self.record_floor
        for p in self.params:
            if p.path == "detector.confidence":
                return min(base, float(min(p.values) if p.values is not None else p.low))
        return base


def _field(path: str, where: str) -> dataclasses.Field:
    from app.config import SECTIONS

    if not isinstance(path, str) or path.count(".") != 1:
        raise SpecError(f"{where}: {path!r} is not SECTION.KEY")
    sec, key = path.split(".")
    if sec not in SECTIONS:
        hint = difflib.get_close_matches(sec, SECTIONS, 1)
        raise SpecError(f"{where}: unknown config section {sec!r}" + (f" (did you mean {hint[0]!r}?)" if hint else ""))
    fields = {f.name: f for f in dataclasses.fields(SECTIONS[sec])}
    if key not in fields:
        hint = difflib.get_close_matches(key, fields, 1)
        raise SpecError(f"{where}: unknown parameter {path!r}" + (f" (did you mean '{sec}.{hint[0]}'?)" if hint else ""))
    return fields[key]


def _check_value(path: str, f: dataclasses.Field, v: Any, where: str) -> Any:
    from app.ocslam.config import ConfigError, coerce_value

    try:
        return coerce_value(path.split(".")[0], f, v)
    except ConfigError as e:
        raise SpecError(f"{where}: {e}") from None


def parse_param(path: str, body: Any) -> Param:
    where = f"params.{path}"
    f = _field(path, where)
    default = f.default if f.default is not dataclasses.MISSING else None
    kind = "int" if type(default) is int else "float" if type(default) is float else "other"
    if isinstance(body, list):
        if not body:
            raise SpecError(f"{where}: an empty list of values")
        return Param(path, kind, values=[_check_value(path, f, v, where) for v in body])
    if not isinstance(body, dict) or "range" not in body:
        raise SpecError(f"{where}: expected a list of values or {{range: [low, high]}} (+ step, log), got {body!r}")
    extra = set(body) - {"range", "step", "log"}
    if extra:
        raise SpecError(f"{where}: unknown key(s) {', '.join(sorted(extra))} (range, step, log)")
    if kind == "other":
        raise SpecError(f"{where}: a range needs a numeric field ({path} is {type(default).__name__}): give a list of values")
    r = body["range"]
    if not (isinstance(r, list) and len(r) == 2 and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in r)):
        raise SpecError(f"{where}.range: expected [low, high] numbers, got {r!r}")
    lo, hi = float(r[0]), float(r[1])
    if not (math.isfinite(lo) and math.isfinite(hi)) or lo >= hi:
        raise SpecError(f"{where}.range: low must be below high, got [{r[0]}, {r[1]}]")
    fmin, fmax = f.metadata.get("min"), f.metadata.get("max")
    if (fmin is not None and lo < fmin) or (fmax is not None and hi > fmax):
        raise SpecError(f"{where}.range: [{r[0]}, {r[1]}] is outside the field's bounds "
                        f"[{fmin if fmin is not None else '-inf'}, {fmax if fmax is not None else 'inf'}]")
    step = body.get("step")
    if step is not None and (isinstance(step, bool) or not isinstance(step, (int, float)) or not step > 0):
        raise SpecError(f"{where}.step: expected a positive number, got {step!r}")
    if kind == "int" and step is not None and float(step) != int(step):
        raise SpecError(f"{where}.step: {path} is an integer field: the step must be an integer")
    log = body.get("log", False)
    if not isinstance(log, bool):
        raise SpecError(f"{where}.log: expected true or false, got {log!r}")
    if log and lo <= 0:
        raise SpecError(f"{where}: a log range needs low > 0")
    return Param(path, kind, low=lo, high=hi, step=float(step) if step is not None else None, log=log)


def parse_spec(data: Any, source: str = "spec") -> Spec:
    """Validate a loaded sweep file (a mapping). Raises :class:`SpecError`."""
    from app.sweep.suite import SuiteError, suite_worlds

    if not isinstance(data, dict):
        raise SpecError(f"{source}: expected a mapping (name, suite, params, sampler, objective, trials)")
    known = {"name", "suite", "only", "config", "set", "params", "sampler", "objective", "trials", "seed", "duration",
             "include_defaults", "record_floor", "scheduler"}
    extra = set(data) - known
    if extra:
        k = sorted(extra)[0]
        hint = difflib.get_close_matches(k, known, 1)
        raise SpecError(f"{source}: unknown key {k!r}" + (f" (did you mean {hint[0]!r}?)" if hint else ""))
    for k in ("suite", "params"):
        if k not in data:
            raise SpecError(f"{source}: missing {k!r}")
    params = data["params"]
    if not isinstance(params, dict) or not params:
        raise SpecError("params: expected a mapping of SECTION.KEY to a range or a list (at least one)")
    plist = [parse_param(str(k), v) for k, v in params.items()]
    only = data.get("only") or []
    if not isinstance(only, list):
        raise SpecError(f"only: expected a list of world names, got {only!r}")
    try:
        n_worlds = len(suite_worlds(data["suite"], [str(n) for n in only]))
    except SuiteError as e:
        raise SpecError(str(e)) from None
    scheduler = parse_scheduler(data.get("scheduler"), n_worlds)
    sampler = data.get("sampler", "random")
    if sampler not in SAMPLERS:
        raise SpecError(f"sampler: {sampler!r} is not one of {', '.join(SAMPLERS)}")
    obj = data.get("objective", "f1")
    if isinstance(obj, str):
        obj = {"metric": obj}
    if not isinstance(obj, dict) or obj.get("metric") not in METRICS or set(obj) - {"metric", "recall_floor"}:
        raise SpecError(f"objective: expected f1 or {{metric: precision_at_recall, recall_floor: R}}, got {data.get('objective')!r}")
    floor = obj.get("recall_floor", 0.0)
    if obj["metric"] == "precision_at_recall" and (isinstance(floor, bool) or not isinstance(floor, (int, float))
                                                    or not 0.0 <= floor <= 1.0 or "recall_floor" not in obj):
        raise SpecError(f"objective.recall_floor: expected a number in [0, 1], got {floor!r}")
    objective = Objective(obj["metric"], float(floor))
    trials = data.get("trials", 20)
    if isinstance(trials, bool) or not isinstance(trials, int) or trials < 1:
        raise SpecError(f"trials: expected a positive integer, got {trials!r}")
    seed = data.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise SpecError(f"seed: expected an integer, got {seed!r}")
    dur = data.get("duration", 1500.0)
    if isinstance(dur, bool) or not isinstance(dur, (int, float)) or not 0 < dur <= 36000:
        raise SpecError(f"duration: expected sim seconds in (0, 36000], got {dur!r}")
    inc = data.get("include_defaults", True)
    if not isinstance(inc, bool):
        raise SpecError(f"include_defaults: expected true or false, got {inc!r}")
    rf = data.get("record_floor")
    if rf is not None and (isinstance(rf, bool) or not isinstance(rf, (int, float)) or not 0.01 <= rf <= 0.99):
        raise SpecError(f"record_floor: expected a detector threshold in [0.01, 0.99], got {rf!r}")
    sets = data.get("set") or {}
    if not isinstance(sets, dict):
        raise SpecError(f"set: expected a mapping SECTION.KEY: value, got {sets!r}")
    for k, v in sets.items():
        _check_value(str(k), _field(str(k), f"set.{k}"), v, f"set.{k}")
    cfg_path = data.get("config")
    if cfg_path is not None and not Path(str(cfg_path)).is_file():
        raise SpecError(f"config: {cfg_path} is not a file")
    name = str(data.get("name") or Path(source).stem)
    spec = Spec(name=name, suite=data["suite"], params=plist, only=[str(n) for n in only],
                config=str(cfg_path) if cfg_path else None, set=dict(sets), sampler=sampler, objective=objective,
                scheduler=scheduler, trials=trials, seed=seed, duration=float(dur), include_defaults=inc,
                record_floor=float(rf) if rf is not None else None, source=source)
    if sampler in ("grid", "oat"):
        for p in plist:
            p.grid_values()
    if rf is not None:
        lows = [min(p.values) if p.values is not None else p.low for p in plist if p.path == "detector.confidence"]
        low = min(lows + [float(spec.base_config().detector.confidence)])
        if low < rf - 1e-12:
            raise SpecError(f"record_floor: {rf} is above a trial's detector.confidence ({low}): those boxes were never recorded")
    try:
        spec.base_config()
    except Exception as e:
        raise SpecError(f"config: {e}") from None
    return spec


def load_spec(path: str | Path) -> Spec:
    """Read and validate a sweep file."""
    import yaml

    p = Path(path)
    try:
        data = yaml.safe_load(p.read_text(encoding="utf-8"))
    except OSError as e:
        raise SpecError(f"{p}: {e.strerror or e}") from None
    except yaml.YAMLError as e:
        raise SpecError(f"{p}: not valid YAML ({str(e).splitlines()[0]})") from None
    return parse_spec(data, str(p))
