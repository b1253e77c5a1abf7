"""A sweep's suite: its worlds, and one recording (a rosbag2 MCAP bag) per world, made once.

A suite is ``zoo-dev`` / ``zoo-test`` (the zoo's split, ``assets/worlds/zoo/split.yaml``), random worlds by
seed range (``{"random": [first, last]}``, the families of ``ocslam bench objects --suite random`` cycling
with the seed), or recorded bags (``{"bags": [paths]}``: OCSLAM recordings with ground truth).

A world is recorded by driving its route headless with the detector on (:func:`record_world`), exactly
as ``ocslam bench objects`` drives it, with ``detector.confidence`` at the sweep's *floor* (the lowest
threshold any trial asks for): the detector's class-aware greedy NMS keeps a box iff no better box of its
class overlaps it, so the boxes a trial at threshold ``t ≥ floor`` would have got are exactly the
recorded boxes with confidence ``≥ t`` (:func:`app.sweep.trace.filter_detections`).

Recordings live in a cache folder, one per world and *recording key* (a hash of everything that changes
what the sensors and the detector produce: the config without its consciousness, UI, server and replay
sections, the world file's or bag's content and the detector model's content (sha256s: an edited world or a
retrained model at the same path is another recording), the floor, the route and the duration); a
recording with the same key is reused.
"""

from __future__ import annotations

import hashlib
import json
import re
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: config sections that do not change a recording (the consciousness is re-run by every trial)
NOT_RECORDED = ("consciousness", "ui", "server", "replay")


class SuiteError(ValueError):
    """A suite cannot be built (unknown name, no worlds, a bag that is not there)."""


@dataclass(frozen=True)
class World:
    """One world of a suite: ``name`` and either a zoo ``file``, a random ``seed`` + ``family``, or a ``bag``."""

    name: str
    file: str | None = None
    seed: int | None = None
    family: str | None = None
    bag: str | None = None

    def job(self) -> dict[str, Any]:
        return {k: v for k, v in (("name", self.name), ("file", self.file), ("seed", self.seed),
                                  ("family", self.family), ("bag", self.bag)) if v is not None}


def suite_worlds(suite: Any, only: list[str] | None = None) -> list[World]:
    """The worlds of a suite spec (see the module docstring). Raises :class:`SuiteError`."""
    worlds: list[World]
    if isinstance(suite, str):
        if suite not in ("zoo-dev", "zoo-test"):
            raise SuiteError(f"suite: unknown suite {suite!r} (zoo-dev, zoo-test, {{random: [first, last]}}, {{bags: [...]}})")
        from app.bench.objects import ZOO_DIR, zoo_split

        worlds = [World(n, file=str(ZOO_DIR / f"{n}.yaml")) for n in zoo_split()[suite.split("-")[1]]]
    elif isinstance(suite, dict) and len(suite) == 1 and "random" in suite:
        r = suite["random"]
        if not (isinstance(r, list) and len(r) == 2 and all(isinstance(v, int) and not isinstance(v, bool) for v in r)):
            raise SuiteError(f"suite.random: expected [first_seed, last_seed] (integers), got {r!r}")
        first, last = r
        # the families cycled with the seed, as in `ocslam bench objects --suite random`
        from app.bench.objects import RANDOM_FAMILIES as fam

        worlds = [World(f"{fam[(s - first) % len(fam)]} {s}", seed=s, family=fam[(s - first) % len(fam)]) for s in range(first, last + 1)]
    elif isinstance(suite, dict) and len(suite) == 1 and "bags" in suite:
        bags = suite["bags"]
        if not isinstance(bags, list) or not all(isinstance(b, str) for b in bags):
            raise SuiteError(f"suite.bags: expected a list of bag paths, got {bags!r}")
        worlds = []
        for b in bags:
            p = Path(b)
            if not p.exists():
                raise SuiteError(f"suite.bags: {b} does not exist")
            worlds.append(World(p.name if p.name != "bag" else p.parent.name, bag=str(p.resolve())))
    else:
        raise SuiteError(f"suite: expected zoo-dev, zoo-test, {{random: [first, last]}} or {{bags: [...]}}, got {suite!r}")
    if only:
        names = {w.name for w in worlds}
        unknown = [n for n in only if n not in names]
        if unknown:
            raise SuiteError(f"only: {', '.join(unknown)} not in the suite ({', '.join(sorted(names))})")
        worlds = [w for w in worlds if w.name in set(only)]
    if not worlds:
        raise SuiteError("suite: no worlds (an empty suite cannot be swept)")
    return worlds


def load_world_of(w: World):
    """The :class:`World` description's simulator world (zoo file or generated layout)."""
    if w.file is not None:
        from app.world.format import load_world

        return load_world(w.file)
    from app.world.generator import generate

    return generate(w.family or "rooms", int(w.seed or 0))


def detector_model_sha256(cfg_dict: dict[str, Any]) -> str | None:
    """sha256 of the ONNX model a config's YOLO detector loads (``None`` for other detectors or a model
    that is not there: the recording will say why); cached by path, size and modification time."""
    det = cfg_dict.get("detector") or {}
    if str(det.get("kind", "yolo")) != "yolo":
        return None
    from app.config import resolve_path
    from app.ocslam.detector import file_sha256

    path = Path(resolve_path(str(det.get("model_path") or "assets/models/detector.onnx")))
    try:
        return file_sha256(path)
    except OSError:
        return None


def recording_key(cfg_dict: dict[str, Any], w: World, floor: float, duration: float) -> str:
    """12 hex digits naming what a recording of ``w`` depends on (see the module docstring)."""
    d = {k: v for k, v in cfg_dict.items() if k not in NOT_RECORDED}
    d = json.loads(json.dumps(d, default=str))
    d.setdefault("detector", {})["confidence"] = round(float(floor), 6)
    d["detector"].pop("calibration", None)  # how the object map reads the scores, not which boxes were recorded
    world = w.job()
    for k in ("file", "bag"):  # what the file holds, not where it lies: an edited world is another recording
        if k in world:
            world[k] = content_sha256(Path(world[k]))
    job: dict[str, Any] = {"cfg": d, "world": world, "duration": float(duration), "v": 3}
    sha = detector_model_sha256(cfg_dict)
    if sha is not None:  # the model's content, not the file it was read from (a model moved into place is the same)
        job["model"] = sha
        d["detector"].pop("model_path", None)
    blob = json.dumps(job, sort_keys=True)
    return hashlib.sha1(blob.encode()).hexdigest()[:12]


def content_sha256(path: Path) -> str:
    """sha256 of a world file or a bag: a ROS 1 bag file, or a rosbag2 folder (its files' relative paths and
    contents, in sorted order: the same recording anywhere is the same hash, another recording another).
    ``missing-<name>`` when it cannot be read: recording or replaying it fails later, with the reader's own
    message."""
    from app.ocslam.detector import file_sha256

    path = Path(path)
    try:
        if path.is_dir():
            files = sorted(f for f in path.rglob("*") if f.is_file())
            if not files:
                raise OSError(f"{path}: an empty folder")
            h = hashlib.sha256()
            for f in files:
                h.update(f"{f.relative_to(path).as_posix()}\0{file_sha256(f)}\n".encode())
            return h.hexdigest()
        return file_sha256(path)
    except OSError:
        return f"missing-{slug(path.name)}"


def slug(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_") or "world"


def recording_dir(cache: Path, cfg_dict: dict[str, Any], w: World, floor: float, duration: float) -> Path:
    return Path(cache) / f"{slug(w.name)}-{recording_key(cfg_dict, w, floor, duration)}"


def recorded(folder: Path) -> dict[str, Any] | None:
    """The ``recording.json`` of a finished recording folder, else None."""
    meta = Path(folder) / "recording.json"
    if not meta.is_file() or not (Path(folder) / "bag" / "metadata.yaml").is_file():
        return None
    try:
        return json.loads(meta.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def record_world(cfg_dict: dict[str, Any], w: World, folder: str | Path, floor: float, duration: float) -> dict[str, Any]:
    """Drive ``w``'s route headless (detector on, ``detector.confidence = floor``) and record it into
    ``folder/bag``; ``folder/recording.json`` is written last (a folder without it is not a recording).
    Returns the recording's description (world, live figures at the floor, times)."""
    from app.config import Config
    from app.pipeline import Pipeline
    from app.ros2.recorder import attach, detach

    folder = Path(folder)
    if w.bag is not None:
        raise SuiteError(f"{w.name}: a recorded bag is not re-recorded")
    cfg = Config.from_dict(cfg_dict)
    cfg.set("detector.confidence", float(floor))
    world = load_world_of(w)
    route = "tour" if "tour" in world.routes else next(iter(world.routes))
    tmp = folder.with_name(folder.name + ".recording")
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir(parents=True)
    t0 = time.perf_counter()
    pipe = Pipeline(cfg, world=world)
    try:
        if pipe.detector is None:
            raise SuiteError(f"{w.name}: no detector ({pipe.detector_error or cfg.detector.kind})")
        pipe.follow_route(route)
        rec = attach(pipe, tmp / "bag", process=False)
        try:
            while pipe.time < duration and pipe.drive_mode == "route":
                pipe.step()
        finally:
            detach(pipe, rec)
        live = pipe.object_report().as_dict()
        sim_time = pipe.time
        route_done = pipe.nav_status == "route done"
    finally:
        pipe.close()
    meta = {"world": w.job(), "route": route, "detector": cfg.detector.kind, "floor": float(floor),
            "detector_model_sha256": detector_model_sha256(cfg_dict),
            "duration": float(duration), "sim_time_s": round(sim_time, 2), "route_done": route_done,
            "wall_s": round(time.perf_counter() - t0, 1), "live_at_floor": {k: live.get(k) for k in
                                                                               ("precision_strict", "recall", "f1")},
            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    (tmp / "recording.json").write_text(json.dumps(meta, indent=1), encoding="utf-8")
    if folder.exists():
        shutil.rmtree(folder)
    tmp.rename(folder)
    return meta
