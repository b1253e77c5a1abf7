"""Ray Tune runs the sweep: suite preparation as Ray tasks, trials as Tune trials, resume by Tune.

:func:`run_sweep` is ``ocslam sweep``'s body:

1. ``ray.init()`` — a local cluster of ``workers`` CPUs on this machine, or the cluster at ``address``
   (``--address``, else ``RAY_ADDRESS``) with no code change. Ray's dashboard and usage statistics are off
   (``include_dashboard=False``, ``RAY_USAGE_STATS_ENABLED=0``): the app never phones home.
2. :func:`prepare` — for a replay sweep, one Ray task per world records it (:func:`app.sweep.suite.record_world`,
   skipped when the cache has it) and builds its trace (:func:`app.sweep.trace.build_trace`, cached
   beside the recording); the traces then travel to the trials through Ray's object store
   (``tune.with_parameters``), so a cluster needs no shared disk.
3. ``tune.Tuner`` — the sampler is Tune's: ``grid`` (``tune.grid_search``), ``random``
   (``BasicVariantGenerator`` with the spec's seed) or ``optuna`` (``OptunaSearch``, TPE); one CPU per
   trial, at most ``workers`` at once. Each finished trial is appended to ``results.jsonl``
   (:class:`ResultsLog`, a Tune callback, which also draws the progress bar). The scheduler is Tune's FIFO
   (every trial scores every world) or, with ``scheduler: asha``, its ``ASHAScheduler``: a trial reports
   after each world (the cheapest first, :func:`world_order`) and stops early when its objective so far is
   not among the best ``1/reduction_factor`` of the trials that reached the same world.
4. Interrupt (Ctrl-C, or SIGINT after ``stop_after`` trials) and resume: Tune saves the experiment's state under
   ``OUT/tune``; :func:`run_sweep` with ``resume=True`` restores it (``Tuner.restore``): finished trials are
   kept, unfinished and not yet started ones run.
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import sys
import time
from pathlib import Path
from typing import Any

from app.sweep.spec import Spec

TUNE_DIR = "tune"
RESULTS = "results.jsonl"


def _ray():
    os.environ["RAY_USAGE_STATS_ENABLED"] = "0"  # never phone home, whatever the environment says
    os.environ.setdefault("RAY_AIR_NEW_OUTPUT", "0")
    os.environ.setdefault("TUNE_DISABLE_AUTO_CALLBACK_LOGGERS", "1")  # no CSV/JSON/TensorBoard per trial
    try:
        import ray
    except ImportError:
        raise SystemExit("ocslam sweep needs Ray Tune: pip install -e '.[scale]' (ray[tune])") from None
    return ray


def init_ray(workers: int, address: str | None = None, quiet: bool = True) -> dict[str, Any]:
    """Start (or join) Ray. Local: ``workers`` CPUs. Returns ``{"address", "cpus", "local"}``."""
    ray = _ray()
    address = address or os.environ.get("RAY_ADDRESS") or None
    if not ray.is_initialized():
        kw: dict[str, Any] = {"include_dashboard": False, "log_to_driver": not quiet, "configure_logging": True,
                              "logging_level": "ERROR"}
        if address is None:
            kw.update(num_cpus=int(workers), object_store_memory=512 * 1024 * 1024)
        ray.init(address=address, **kw)
    res = ray.cluster_resources()
    return {"address": address or "local", "cpus": res.get("CPU", 0.0), "local": address is None}


# ------------------------------------------------------------------------------------------------
# Suite preparation
# ------------------------------------------------------------------------------------------------


def trace_key(cfg_dict: dict[str, Any]) -> str:
    """What a trace depends on beyond its recording: the SLAM, the replay settings, the fixed fields."""
    from app.sweep.trace import TRACE_FIXED

    c = cfg_dict.get("consciousness", {})
    d = {"slam": cfg_dict.get("slam"), "replay": cfg_dict.get("replay"),
         "fixed": {k: c.get(k) for k in (*TRACE_FIXED, "corner_check")}, "v": 1}
    return hashlib.sha1(json.dumps(d, sort_keys=True, default=str).encode()).hexdigest()[:12]


def prepare_world(cfg_dict: dict[str, Any], world: Any, cache: str, floor: float, duration: float) -> tuple[str, dict[str, Any]]:
    """Record ``world`` if the cache lacks it and build (or load) its trace; returns the trace's file."""
    from app.config import Config
    from app.sweep.suite import record_world, recorded, recording_dir
    from app.sweep.trace import build_trace

    t0 = time.perf_counter()
    info: dict[str, Any] = {"world": world.name}
    if world.bag is not None:
        bag = Path(world.bag)
        from app.sweep.suite import content_sha256

        folder = Path(cache) / f"bag-{content_sha256(bag)[:12]}"  # by content: a re-recorded bag is another trace
        folder.mkdir(parents=True, exist_ok=True)
        info["recorded"] = "given"
        rec_floor = 0.0
    else:
        folder = recording_dir(Path(cache), cfg_dict, world, floor, duration)
        meta = recorded(folder)
        info["recorded"] = "cached" if meta else "now"
        if meta is None:
            meta = record_world(cfg_dict, world, folder, floor, duration)
        info["record_wall_s"] = meta.get("wall_s")
        info["sim_time_s"] = meta.get("sim_time_s")
        bag = folder / "bag"
        rec_floor = floor
    tfile = folder / f"trace-{trace_key(cfg_dict)}.pkl"
    if not tfile.is_file():
        cfg = Config.from_dict(cfg_dict)
        cfg.set("detector.confidence", max(float(cfg.detector.confidence), 0.01))
        tr = build_trace(bag, cfg, world.name, rec_floor)
        tmp = tfile.with_suffix(".tmp")
        with open(tmp, "wb") as f:
            pickle.dump(tr, f, protocol=pickle.HIGHEST_PROTOCOL)
        tmp.replace(tfile)
        info.update(trace="built", **tr.info)
    else:
        info["trace"] = "cached"
    info["prepare_s"] = round(time.perf_counter() - t0, 1)
    return str(tfile), info


def prepare(spec: Spec, cache: Path, quiet: bool = False) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """One Ray task per world (see :func:`prepare_world`); returns ``{world name: Trace}`` and the tasks' info."""
    ray = _ray()
    from app.sweep.suite import suite_worlds

    worlds = suite_worlds(spec.suite, spec.only)
    cfg_dict = spec.base_config().to_dict()
    floor = spec.floor()
    task = ray.remote(num_cpus=1, max_retries=0)(prepare_world)
    refs = {task.remote(cfg_dict, w, str(Path(cache).absolute()), floor, spec.duration): w for w in worlds}
    bar = _bar(len(refs), "preparing worlds", quiet)
    out: dict[str, str] = {}
    infos: list[dict[str, Any]] = []
    pending = list(refs)
    while pending:
        done, pending = ray.wait(pending, num_returns=1)
        path, info = ray.get(done[0])
        out[refs[done[0]].name] = path
        infos.append(info)
        if bar is not None:
            bar.set_postfix_str(f"{info['world']}: {info['recorded']}, trace {info['trace']}")
            bar.update(1)
    if bar is not None:
        bar.close()
    traces = {}
    for w in worlds:  # the suite's order
        with open(out[w.name], "rb") as f:
            traces[w.name] = pickle.load(f)
    return traces, infos


def _bar(total: int, desc: str, quiet: bool):
    if quiet:
        return None
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    return tqdm(total=total, desc=desc, unit="world" if "world" in desc else "trial", file=sys.stderr, dynamic_ncols=True)


# ------------------------------------------------------------------------------------------------
# Trials
# ------------------------------------------------------------------------------------------------


def world_order(ctx: dict[str, Any]) -> list[str]:
    """The order a trial scores the worlds in: the suite's, or with ASHA the cheapest first (fewest recorded
    frames; a trial that stops early has then cost little, and every trial reaches a rung through the same
    worlds, so the trials it compares there were scored on the same worlds)."""
    names = [w.name for w in ctx["worlds"]]
    traces = ctx["traces"]
    if ctx.get("scheduler") == "asha" and traces is not None:
        return sorted(names, key=lambda n: (int(traces[n].info.get("frames", 0)), names.index(n)))
    return names


def run_trial(config: dict[str, Any], ctx: dict[str, Any]) -> None:
    """Tune's function trainable: score one configuration over the suite world by world; report once at
    the end (``fifo``) or after every world (``asha``, whose scheduler may stop the trial between worlds)."""
    from ray import tune

    from app.sweep.spec import Objective
    from app.sweep.trial import mean_of, score_headless, score_replay, trial_config

    t0, c0 = time.perf_counter(), time.process_time()
    cfg = trial_config(ctx["base"], config)
    obj = Objective(**ctx["objective"])
    worlds = {w.name: w for w in ctx["worlds"]}
    order = world_order(ctx)
    each = ctx.get("scheduler") == "asha"
    per: dict[str, dict[str, Any]] = {}
    for i, name in enumerate(order):
        if ctx["traces"] is not None:
            per.update(score_replay(cfg, {name: ctx["traces"][name]}))
        else:
            per.update(score_headless(cfg, [worlds[name]], ctx["duration"]))
        if each or i == len(order) - 1:
            mean = mean_of(per)
            tune.report({"objective": obj.value(mean), **{f"mean_{k}": v for k, v in mean.items()},
                         "worlds_done": len(per), "complete": len(per) == len(order),
                         "per_world_json": json.dumps(per, default=float), "trial_s": round(time.perf_counter() - t0, 3),
                         "trial_cpu_s": round(time.process_time() - c0, 3), "pid": os.getpid(),
                         "host": os.uname().nodename})


def param_space(spec: Spec) -> dict[str, Any]:
    from ray import tune

    space: dict[str, Any] = {}
    for p in spec.params:
        if spec.sampler == "grid":
            space[p.path] = tune.grid_search(p.grid_values())
        elif spec.sampler == "oat":
            space[p.path] = tune.choice(p.grid_values())  # every trial is one of the points to evaluate
        elif p.values is not None:
            space[p.path] = tune.choice(p.values)
        elif p.kind == "int":
            lo, hi = int(round(p.low)), int(round(p.high))
            space[p.path] = tune.qrandint(lo, hi, int(p.step)) if p.step else tune.randint(lo, hi + 1)
        elif p.step:
            space[p.path] = tune.qloguniform(p.low, p.high, p.step) if p.log else tune.quniform(p.low, p.high, p.step)
        else:
            space[p.path] = tune.loguniform(p.low, p.high) if p.log else tune.uniform(p.low, p.high)
    return space


def _search_alg(spec: Spec, workers: int):
    if spec.sampler == "optuna":
        try:
            from ray.tune.search.optuna import OptunaSearch
        except ImportError:
            raise SystemExit("sampler: optuna needs the optuna package (pip install optuna)") from None
        return OptunaSearch(metric="objective", mode="max", seed=spec.seed,
                            points_to_evaluate=[spec.defaults()] if spec.include_defaults else None)
    from ray.tune.search.basic_variant import BasicVariantGenerator

    points = [spec.defaults()] if spec.include_defaults and spec.sampler == "random" else None
    if spec.sampler == "oat":
        points = spec.oat_points()
    return BasicVariantGenerator(random_state=spec.seed, max_concurrent=workers, points_to_evaluate=points)


def _scheduler(spec: Spec, n_worlds: int):
    """Tune's FIFO scheduler (every trial runs to its end), or its ASHAScheduler over the worlds: a trial's
    ``training_iteration`` is the number of worlds it has scored (``run_trial`` reports after each)."""
    if spec.scheduler.kind != "asha":
        return None
    from ray.tune.schedulers import ASHAScheduler

    return ASHAScheduler(time_attr="training_iteration", max_t=n_worlds, grace_period=spec.scheduler.grace_worlds,
                         reduction_factor=spec.scheduler.reduction_factor)


def _callbacks(out: Path, total: int, stop_after: int | None, quiet: bool):
    from ray import tune

    class ResultsLog(tune.Callback):
        """Appends each finished trial (scored on every world, or stopped early by ASHA: ``complete`` false,
        ``worlds_done`` worlds) to ``results.jsonl`` and moves the progress bar; after ``stop_after`` trials in
        this session it interrupts the sweep as Ctrl-C does (SIGINT: Tune saves its state and the trials still
        running are resumed by ``Tuner.restore``)."""

        def __init__(self, path: str, total: int, quiet: bool, stop_after: int | None) -> None:
            self.path, self.total, self.quiet, self.stop_after = path, total, quiet, stop_after
            self._bar = None
            self._seen: set[str] = set()

        def __getstate__(self):  # the bar does not travel with Tune's saved state
            d = dict(self.__dict__)
            d["_bar"] = None
            return d

        def setup(self, **info):
            done = len(read_results(Path(self.path)))
            self._bar = _bar(self.total, "trials", self.quiet)
            if self._bar is not None and done:
                self._bar.update(min(done, self.total))

        def on_trial_complete(self, iteration, trials, trial, **info):
            from app.sweep.trial import clean

            result = trial.last_result or {}
            if "objective" not in result or trial.trial_id in self._seen:
                return  # never reported (failed before its first world), or already written
            row = {"trial_id": trial.trial_id, "params": clean(dict(trial.config)), "objective": result.get("objective"),
                   **{k: result.get(k) for k in ("mean_precision_strict", "mean_recall", "mean_f1", "mean_pos_err_mean_m",
                                                 "worlds_done", "complete", "trial_s", "trial_cpu_s", "pid", "host")},
                   "per_world": json.loads(result.get("per_world_json") or "{}"), "time": time.time()}
            with open(self.path, "a", encoding="utf-8") as f:
                f.write(json.dumps(row, default=float) + "\n")
            if self._bar is not None:
                self._bar.update(1)
                stop = "" if row.get("complete", True) else f", stopped after {row.get('worlds_done')} worlds"
                self._bar.set_postfix_str(f"F1 {row['mean_f1']:.3f}, {row['trial_s']:.1f} s{stop}")
            self._seen.add(trial.trial_id)
            if self.stop_after is not None and len(self._seen) == self.stop_after:
                import signal

                os.kill(os.getpid(), signal.SIGINT)

        def on_experiment_end(self, trials, **info):
            if self._bar is not None:
                self._bar.close()

    return [ResultsLog(str(out / RESULTS), total, quiet, stop_after)]


def read_results(path: Path) -> list[dict[str, Any]]:
    """The trials in ``results.jsonl`` (one per trial id, the last line wins; a torn last line is skipped)."""
    rows: dict[str, dict[str, Any]] = {}
    if not Path(path).is_file():
        return []
    for line in Path(path).read_text(encoding="utf-8").splitlines():
        try:
            r = json.loads(line)
        except ValueError:
            continue
        if isinstance(r, dict) and "trial_id" in r:
            rows[r["trial_id"]] = r
    return sorted(rows.values(), key=lambda r: r.get("time", 0.0))


def total_trials(spec: Spec) -> int:
    if spec.sampler == "oat":
        return len(spec.oat_points())
    if spec.sampler == "grid":
        n = 1
        for p in spec.params:
            n *= len(p.grid_values())
        return n
    return spec.trials


def run_sweep(spec: Spec, out: Path, *, workers: int = 2, address: str | None = None, cache: Path | None = None,
              resume: bool = False, stop_after: int | None = None, quiet: bool = False) -> dict[str, Any]:
    """Prepare the suite and run (or resume) the trials; returns what happened (for ``sweep.json``)."""
    ray = _ray()
    from ray import tune

    out = Path(out).absolute()
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    cluster = init_ray(workers, address, quiet=True)
    cache = Path(cache or out.parent / "sweep-cache").absolute()
    base = spec.base_config()
    traces = None
    infos: list[dict[str, Any]] = []
    if spec.replayable:
        traces, infos = prepare(spec, cache, quiet)
    t_prep = time.perf_counter() - t0
    from app.sweep.suite import suite_worlds

    worlds = suite_worlds(spec.suite, spec.only)
    ctx = {"base": base.to_dict(), "traces": traces, "worlds": worlds, "scheduler": spec.scheduler.kind,
           "duration": spec.duration, "objective": {"metric": spec.objective.metric, "recall_floor": spec.objective.recall_floor}}
    trainable = tune.with_resources(tune.with_parameters(run_trial, ctx=ctx), {"cpu": 1})
    exp = out / TUNE_DIR
    total = total_trials(spec)
    callbacks = _callbacks(out, total, stop_after, quiet)
    t1 = time.perf_counter()
    if resume and tune.Tuner.can_restore(str(exp)):
        tuner = tune.Tuner.restore(str(exp), trainable, resume_unfinished=True, resume_errored=True)
        # this session's callbacks (progress, --stop-after), not the interrupted session's pickled ones
        local = getattr(tuner, "_local_tuner", None)
        if local is not None and hasattr(local, "_run_config"):
            local._run_config.callbacks = callbacks
        resumed = True
    else:
        if exp.exists() and not resume:
            raise SystemExit(f"ocslam sweep: {out} has a sweep already: --resume it, or choose another --out")
        resumed = False
        tuner = tune.Tuner(
            trainable,
            param_space=param_space(spec),
            tune_config=tune.TuneConfig(metric="objective", mode="max", search_alg=_search_alg(spec, workers),
                                        scheduler=_scheduler(spec, len(worlds)),
                                        num_samples=1 if spec.sampler == "grid" else total_trials(spec),
                                        max_concurrent_trials=workers, reuse_actors=True),
            run_config=tune.RunConfig(name=TUNE_DIR, storage_path=str(out), callbacks=callbacks,
                                      verbose=0, log_to_file=True),
        )
    tuner.fit()
    wall = time.perf_counter() - t1
    rows = read_results(out / RESULTS)
    return {"cluster": cluster, "prepare_s": round(t_prep, 1), "trials_wall_s": round(wall, 1), "resumed": resumed,
            "trials_done": len(rows), "trials_total": total, "prepare": infos, "workers": workers, "cache": str(cache),
            "ray": ray.__version__}
