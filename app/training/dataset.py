"""Auto-labelled YOLO datasets rendered by the simulator (``ocslam dataset``).

For each world (random apartments from ``random_world(seed)`` and, for training, the paper's apartment)
one process renders camera views at robot height: looking at objects from all sides and distances
(often off-centre, so objects are truncated by the frame edge), along the world's routes, and from
random free poses. Labels come from the segmentation mask (:mod:`app.training.labels`): the tight box of each
object's visible pixels, kept when enough of the object is visible.

**Visible fraction.** ``visible pixels / unoccluded pixels``. The unoccluded count comes from a second
render of the object *alone* (its own small pybullet client) through an off-centre projection that
covers exactly the object's projected bounding box on the camera's image plane extended past the frame,
at the same pixel scale (:class:`app.training.silhouettes.SilhouetteRenderer`). Occlusion by other geometry and
truncation by the side and bottom frame edges therefore both lower the fraction, with the renderer's
own rasterisation on both sides of the ratio (a fully visible object scores 1.0). What lies above the
top edge does not count: the robot's low, level camera cuts every door, shelf and person there.

**Domain randomisation** (:mod:`app.training.randomization`; per world, re-drawn every ``rerandomize_every`` images): light direction,
colour and intensity (ambient/diffuse/specular, sometimes shadows); floor and wall colours and
procedural textures (planks, tiles, checker, carpet noise, stripes, plain) on overlay meshes; object
colour jitter; distractor objects of no class (``pybullet_data/random_urdfs``, scaled and recoloured);
camera height and pitch jitter; sensor effects (gamma/contrast/colour balance, blur, motion blur,
Gaussian noise).

**Layout families**: world ``i`` of a dataset made with ``--seed S`` and ``--families F₀,F₁,…`` is
``random_world(1000·S + i, family=F[i mod len(F)])`` (default: all four families, ``rooms``, ``corridor``,
``lshape``, ``openplan``, so the detector sees the furniture groups and layouts the app meets; ``--families
rooms`` is the recipe of datasets made before 2026-12-03). Datasets with different seeds share no world.

**Views without a label**: a view is kept with probability ``empty_keep_prob`` when no object is labelled
in it. One that surely holds no label (every object's box projects too small, off the image or behind the
camera: :func:`~app.training.labels.may_be_labelled`) is kept or dropped before it is rendered, with the same
draw, so the dataset is the same, rendered faster.

**Split by world**: a seeded choice of random worlds is the validation split; the apartment is always
training data; no world is in both.

**Image files**: PNG stored without compression by default (the renders carry sensor noise, which deflate
shrinks only to about 60 % at 2 ms an image, a sixth of a render; the pixels are the same either way);
``compress_images`` writes OpenCV's default compressed PNG instead (135 against 225 KB at 320×240).

Output (``DIR``): ``images/{train,val}/*.png``, ``labels/{train,val}/*.txt`` (YOLO), ``data.yaml``
(ultralytics; the 11 classes in ``CLASS_NAMES`` order; an ``ocslam`` block with the command, seed and
counts), ``annotations_{train,val}.json`` (COCO, with not-kept visible objects as ``iscrowd`` ignore
regions and each box's visible fraction) for ``ocslam bench detector``.
"""

from __future__ import annotations

import importlib
import json
import multiprocessing as mp
import os
import queue as queue_mod
import shlex
import signal
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml

from app.ocslam.messages import CLASS_INDEX, CLASS_NAMES, CameraInfo
from app.training.labels import (
    LabelFilter,
    make_labels,
    may_be_labelled,
    object_boxes,
    visible_boxes,
    yolo_lines,
)
from app.training.randomization import PNG_STORED, Randomizer, sensor_effects
from app.training.silhouettes import ModelClient, SilhouetteRenderer, label_silhouettes
from app.training.viewpoints import sample_viewpoint

__all__ = [
    "DatasetOptions",
    "build_dataset",
    "parse_imgsz",
    "plan_worlds",
    "render_world",
]

APARTMENT = "assets/worlds/apartment.yaml"
#: every layout family of ``random_world`` (the default of ``--families``)
ALL_FAMILIES: tuple[str, ...] = ("rooms", "corridor", "lshape", "openplan")


@dataclass
class DatasetOptions:
    out: Path
    worlds: int = 40
    per_world: int = 45
    seed: int = 1
    imgsz: tuple[int, int] = (320, 240)
    workers: int = 2
    val_fraction: float = 0.15
    apartment: bool = True
    apartment_images: int | None = None  # default: 2 × per_world
    label_filter: LabelFilter = field(default_factory=LabelFilter)
    randomize: bool = True
    distractors: tuple[int, int] = (2, 8)
    rerandomize_every: int = 10
    empty_keep_prob: float = 0.15  # keep this share of views in which no object is labelled
    families: tuple[str, ...] = ALL_FAMILIES  # world i is of family families[i mod len(families)]
    #: camera renderer (``sim.renderer``): ``tiny`` (every committed model's data), ``egl`` (the app's where it
    #: loads; its images differ in shading), ``auto``
    renderer: str = field(default_factory=lambda: os.environ.get("OCSLAM_RENDERER", "tiny"))
    close_views: float = 0.0  # share of views from under or beside an object (``sample_viewpoint``)
    compress_images: bool = False  # PNG with OpenCV's default compression instead of stored (same pixels)
    command: str | None = None


def png_flags(compress: bool) -> list[int]:
    """``cv2.imwrite`` flags for a dataset image: OpenCV's default PNG compression, or stored."""
    return [] if compress else list(PNG_STORED)


def parse_imgsz(s: str | Sequence[int]) -> tuple[int, int]:
    """``"320x240"`` / ``"320×240"`` / ``(320, 240)`` → ``(320, 240)``."""
    if not isinstance(s, str):
        w, h = s
        return int(w), int(h)
    parts = s.lower().replace("×", "x").split("x")
    if len(parts) != 2:
        raise ValueError(f"image size must be W×H (e.g. 320x240), got {s!r}")
    w, h = int(parts[0]), int(parts[1])
    if not (32 <= w <= 4096 and 24 <= h <= 4096):
        raise ValueError(f"image size {w}×{h} is out of range")
    return w, h


# ----------------------------------------------------------------------------------------------
# Worlds and the split
# ----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class WorldTask:
    index: int  # position in the dataset (file name prefix)
    kind: str  # "random" | "apartment"
    world_seed: int  # random_world seed (random) or 0
    split: str  # "train" | "val"
    images: int
    family: str = "rooms"  # random_world layout family (random worlds)


def plan_worlds(opts: DatasetOptions) -> list[WorldTask]:
    """The dataset's worlds and their split: validation worlds are a seeded choice of random worlds."""
    n = int(opts.worlds)
    rng = np.random.default_rng([int(opts.seed), 0xDA7A])
    n_val = int(round(opts.val_fraction * n))
    if opts.val_fraction > 0 and n >= 2:
        n_val = min(max(n_val, 1), n if opts.val_fraction >= 1.0 else n - 1)
    elif opts.val_fraction >= 1.0:
        n_val = n
    val = set(rng.permutation(n)[:n_val].tolist()) if n_val else set()
    fams = tuple(opts.families) or ("rooms",)
    tasks = [
        WorldTask(i, "random", 1000 * int(opts.seed) + i, "val" if i in val else "train", int(opts.per_world),
                  fams[i % len(fams)])
        for i in range(n)
    ]
    if opts.apartment:
        k = opts.apartment_images if opts.apartment_images is not None else 2 * int(opts.per_world)
        tasks.append(WorldTask(n, "apartment", 0, "train", int(k)))
    return tasks


# ----------------------------------------------------------------------------------------------
# Rendering one world (runs in a worker process)
# ----------------------------------------------------------------------------------------------

_progress_queue = None
_worker_clients: ModelClient | None = None  # a worker's silhouette models' client, kept for all its worlds
_worker_render: dict[str, Any] = {}  # a worker's RenderClient per requested renderer, kept for all its worlds


def _render_client(requested: str) -> Any:
    """In a dataset worker, its :class:`~app.sim.renderer.RenderClient` for ``requested`` (opened on first
    use; the EGL plugin loads once, not once a world); ``None`` elsewhere (each world opens its own)."""
    if _worker_clients is None:
        return None
    if requested not in _worker_render:
        from app.sim.renderer import RenderClient

        _worker_render[requested] = RenderClient(requested)
    return _worker_render[requested]


def _init_worker(q) -> None:
    """In each worker: the default SIGTERM action (the parent's handler, which turns SIGTERM into
    KeyboardInterrupt, must not be inherited: a worker that unwinds while holding the progress queue's
    lock hangs everyone), Ctrl-C left to the parent, one OpenMP thread and one llvmpipe thread."""
    global _progress_queue, _worker_clients
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _progress_queue = q
    _worker_clients = ModelClient()  # connected on first use, in this process; it ends with it
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    # llvmpipe's rasteriser threads: one per core by default; with a worker per core they only contend
    # (the 40-world recipe: 48 s against 52 s)
    os.environ.setdefault("LP_NUM_THREADS", "1")


#: what a worker imports to render a world (``yourdfpy`` and ``trimesh`` alone take about a second): the parent
#: imports them before it forks the workers, which inherit them instead of each importing them again
WORKER_MODULES: tuple[str, ...] = (
    "pybullet",
    "app.config",
    "app.sim_world",
    "app.world.format",
    "app.world.generator",
    "app.training.part_hulls",
)


def preload_worker_modules() -> None:
    """Import :data:`WORKER_MODULES` in this process (the parent, before it forks the workers; safe to call
    from a thread, e.g. while the EGL probe runs)."""
    for name in WORKER_MODULES:
        importlib.import_module(name)


class DatasetError(RuntimeError):
    """Rendering failed (e.g. a worker process died); the message names the worlds left unrendered."""


def render_world(task: WorldTask, opts: DatasetOptions, progress: Callable[[int], None] | None = None) -> list[dict]:
    """Render ``task.images`` views of one world into ``opts.out``; returns the image records."""
    from app.config import Config, resolve_path
    from app.sim_world import SimWorld
    from app.world.format import load_world
    from app.world.generator import random_world

    if progress is None and _progress_queue is not None:
        progress = _progress_queue.put
    if task.kind == "apartment":
        world = load_world(resolve_path(APARTMENT))
    else:
        world = random_world(task.world_seed, family=task.family)
    cfg = Config()
    W, H = opts.imgsz
    rng = np.random.default_rng([int(opts.seed), int(task.index), 0x5EED])
    fx_rng = np.random.default_rng([int(opts.seed), int(task.index), 0xEFFEC7])  # sensor effects: never move a view
    sim = SimWorld(world, cfg, seed=int(task.world_seed), renderer=opts.renderer, client=_render_client(opts.renderer))
    records: list[dict] = []
    img_dir = Path(opts.out) / "images" / task.split
    lbl_dir = Path(opts.out) / "labels" / task.split
    img_dir.mkdir(parents=True, exist_ok=True)
    lbl_dir.mkdir(parents=True, exist_ok=True)
    class_of = {i: CLASS_INDEX[o.label] for i, o in enumerate(world.objects)}
    base_z = float(sim.robot_model.T_base_camera_optical[2, 3])
    fam = "" if task.family == "rooms" else f", family={task.family!r}"
    world_name = "apartment" if task.kind == "apartment" else f"random_world({task.world_seed}{fam})"
    silhouettes = SilhouetteRenderer(world, cfg.camera.near_m, cfg.camera.far_m, clients=_worker_clients)
    boxes = object_boxes(world.objects)
    K = CameraInfo.from_fov(W, H, cfg.camera.hfov_rad).K
    near = float(cfg.camera.near_m)
    min_px, min_box = opts.label_filter.scaled(W)
    png = png_flags(opts.compress_images)
    with tempfile.TemporaryDirectory(prefix="ocslam-tex-") as tmp:
        rz = Randomizer(sim, rng, Path(tmp), opts.distractors if opts.randomize else (0, 0))
        try:
            if opts.randomize:
                rz.randomize_scene()
            k = 0
            attempts = 0
            while k < task.images and attempts < task.images * 6:
                attempts += 1
                pose = sample_viewpoint(sim, rz, rng, close_views=opts.close_views)
                if pose is None:
                    continue
                cam_z = base_z + float(rng.uniform(-0.05, 0.07)) if opts.randomize else None
                pitch = float(rng.uniform(-0.08, 0.12)) if opts.randomize else 0.0
                light = rz.sample_light() if opts.randomize else None
                # a view that surely holds no label is kept or dropped before it is rendered (the same draw
                # as after rendering it: nothing in between draws from rng)
                T_wc = sim.view_camera_pose(pose, camera_z=cam_z, pitch_rad=pitch)
                empty = not may_be_labelled(boxes, T_wc, K, W, H, near, min_px, min_box)
                if empty and rng.random() > opts.empty_keep_prob:
                    continue
                frame = sim.render_view(pose, width=W, height=H, camera_z=cam_z, pitch_rad=pitch, light=light, segmentation=True)
                vis = visible_boxes(frame.segmentation)
                cands = {i: v for i, v in vis.items() if i in class_of and v[4] >= min_px}
                sil = label_silhouettes(silhouettes, frame.T_world_camera, frame.info.K, W, H, cands, opts.label_filter)
                full = {k: v[0] for k, v in sil.items()}
                inside = {k: v[1] for k, v in sil.items()}
                labels = make_labels(frame.segmentation, class_of, full, opts.label_filter, inside, boxes=vis)
                if not empty and not any(lb.keep for lb in labels) and rng.random() > opts.empty_keep_prob:
                    continue
                rgb = sensor_effects(frame.image.data, fx_rng) if opts.randomize else frame.image.data
                stem = f"w{task.index:03d}_{k:04d}"
                cv2.imwrite(str(img_dir / f"{stem}.png"), rgb[:, :, ::-1], png)
                lines = yolo_lines(labels, W, H)
                (lbl_dir / f"{stem}.txt").write_text("\n".join(lines) + ("\n" if lines else ""))
                records.append(
                    {
                        "file_name": f"images/{task.split}/{stem}.png",
                        "width": W,
                        "height": H,
                        "split": task.split,
                        "world": world_name,
                        "pose": [round(pose.x, 3), round(pose.y, 3), round(pose.yaw, 4)],
                        "labels": [
                            {
                                "class_id": lb.class_id,
                                "bbox": [lb.x1, lb.y1, lb.x2, lb.y2],
                                "keep": lb.keep,
                                "visible_pixels": lb.visible_pixels,
                                "visible_fraction": round(lb.visible_fraction, 4),
                                "in_frame_fraction": round(lb.in_frame_fraction, 4),
                                "object": world.object_name(lb.object_id),
                            }
                            for lb in labels
                        ],
                    }
                )
                k += 1
                if progress is not None:
                    progress(1)
                if opts.randomize and k % max(1, opts.rerandomize_every) == 0 and k < task.images:
                    rz.randomize_scene()
        finally:
            sim.close()
            silhouettes.close()
    return records


# ----------------------------------------------------------------------------------------------
# The whole dataset
# ----------------------------------------------------------------------------------------------


def _coco(records: list[dict]) -> dict[str, Any]:
    images, anns = [], []
    for i, r in enumerate(records):
        images.append({k: r[k] for k in ("file_name", "width", "height", "world", "pose")} | {"id": i + 1})
        for lb in r["labels"]:
            x1, y1, x2, y2 = lb["bbox"]
            anns.append(
                {
                    "id": len(anns) + 1,
                    "image_id": i + 1,
                    "category_id": lb["class_id"] + 1,
                    "bbox": [x1, y1, x2 - x1, y2 - y1],
                    "area": (x2 - x1) * (y2 - y1),
                    "iscrowd": 0 if lb["keep"] else 1,
                    "visible_fraction": lb["visible_fraction"],
                    "in_frame_fraction": lb["in_frame_fraction"],
                    "visible_pixels": lb["visible_pixels"],
                    "object": lb["object"],
                }
            )
    cats = [{"id": i + 1, "name": n} for i, n in enumerate(CLASS_NAMES)]
    return {"images": images, "annotations": anns, "categories": cats}


def _procs(ex: Any) -> list[Any]:
    """The executor's worker processes (``ProcessPoolExecutor._processes``; empty once shut down)."""
    return list((getattr(ex, "_processes", None) or {}).values())


def _run_workers(tasks: list[WorldTask], opts: DatasetOptions, render: Callable[..., list[dict]], bar: Any) -> list[dict]:
    """Render ``tasks`` in ``opts.workers`` forked processes (biggest worlds first); the records.

    A worker that dies (killed, crashed) breaks the pool: the other workers are stopped and
    :class:`DatasetError` names the worlds not rendered, instead of waiting forever for its result.
    A normal end shuts the workers down cleanly (no terminate while one may hold a queue lock)."""
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    ctx = mp.get_context("fork")
    preload_worker_modules()  # forked workers inherit them
    q = ctx.Queue()
    records: list[dict] = []
    ex = ProcessPoolExecutor(min(opts.workers, len(tasks)), mp_context=ctx, initializer=_init_worker, initargs=(q,))

    def drain() -> None:
        try:
            while True:
                bar.update(q.get_nowait())
        except (queue_mod.Empty, OSError, ValueError):
            pass

    clean = False
    seen: dict[int, Any] = {}  # every worker process ever started (the executor forgets broken ones)

    def died(left: list[int]) -> DatasetError:
        for p in seen.values():
            p.join(timeout=1.0)
        codes = sorted({p.exitcode for p in seen.values() if p.exitcode})
        how = f" (exit codes {', '.join(map(str, codes))})" if codes else ""
        return DatasetError(
            f"a rendering worker process died{how}; worlds not rendered: {', '.join(map(str, sorted(left)))}. "
            "The dataset is incomplete; run the command again"
        )

    try:
        order = sorted(tasks, key=lambda t: -t.images)
        pending = {ex.submit(render, order[0], opts): order[0]}
        seen.update({p.pid: p for p in _procs(ex)})  # fork: the first submit starts every worker
        for i, t in enumerate(order[1:], 1):
            try:
                pending[ex.submit(render, t, opts)] = t
            except BrokenProcessPool:  # a worker died while the rest were being queued
                raise died([u.index for u in order[i:]] + [u.index for u in pending.values()]) from None
        while pending:
            done, _ = wait(list(pending), timeout=0.2, return_when=FIRST_COMPLETED)
            seen.update({p.pid: p for p in _procs(ex)})
            drain()
            for f in done:
                t = pending.pop(f)
                try:
                    records += f.result()
                except BrokenProcessPool:
                    raise died([t.index] + [u.index for u in pending.values()]) from None
        drain()
        clean = True
    finally:
        if clean:
            ex.shutdown(wait=True)
        else:  # error or Ctrl-C/SIGTERM: stop the workers now, never wait on them
            procs = _procs(ex)
            ex.shutdown(wait=False, cancel_futures=True)
            for p in procs:
                if p.is_alive():
                    p.kill()
            for p in procs:
                p.join(timeout=5)
        q.close()
        q.cancel_join_thread()
    return records


def build_dataset(opts: DatasetOptions, progress: bool = True, *, render: Callable[..., list[dict]] | None = None) -> dict[str, Any]:
    """Render every world (in ``opts.workers`` processes) and write the YOLO dataset. Returns a summary.

    ``render(task, opts)`` renders one world (default :func:`render_world`; a module-level function, since
    workers receive it by reference). :class:`DatasetError` if a worker process dies."""
    render = render or render_world
    from tqdm import tqdm

    out = Path(opts.out)
    out.mkdir(parents=True, exist_ok=True)
    tasks = plan_worlds(opts)
    total = sum(t.images for t in tasks)
    t0 = time.monotonic()
    records: list[dict] = []
    bar = tqdm(total=total, desc="rendering", unit="img", disable=not progress, file=sys.stderr, smoothing=0.05)
    try:
        if opts.workers <= 1 or len(tasks) == 1:
            for t in tasks:
                records += render(t, opts, progress=bar.update)
        else:
            records = _run_workers(tasks, opts, render, bar)
    finally:
        bar.close()
    records.sort(key=lambda r: r["file_name"])
    by_split = {s: [r for r in records if r["split"] == s] for s in ("train", "val")}
    for s, recs in by_split.items():
        (out / "images" / s).mkdir(parents=True, exist_ok=True)
        (out / "labels" / s).mkdir(parents=True, exist_ok=True)
        (out / f"annotations_{s}.json").write_text(json.dumps(_coco(recs)))
    counts = {s: {n: 0 for n in CLASS_NAMES} for s in by_split}
    for s, recs in by_split.items():
        for r in recs:
            for lb in r["labels"]:
                if lb["keep"]:
                    counts[s][CLASS_NAMES[lb["class_id"]]] += 1
    worlds = {s: sorted({r["world"] for r in recs}) for s, recs in by_split.items()}
    meta = {
        "command": opts.command,
        "seed": int(opts.seed),
        "worlds": int(opts.worlds),
        "per_world": int(opts.per_world),
        "imgsz": list(opts.imgsz),
        "families": list(opts.families),
        "renderer": str(opts.renderer),
        "images": {s: len(r) for s, r in by_split.items()},
        "boxes": {s: sum(c.values()) for s, c in counts.items()},
        "train_worlds": worlds["train"],
        "val_worlds": worlds["val"],
        "label_filter": asdict(opts.label_filter),
        "randomize": opts.randomize,
        "compress_images": bool(opts.compress_images),
        "render_s": round(time.monotonic() - t0, 1),
    }
    data = {
        "train": "images/train",
        "val": "images/val",
        "nc": len(CLASS_NAMES),
        "names": {i: n for i, n in enumerate(CLASS_NAMES)},
        "ocslam": meta,
    }
    (out / "data.yaml").write_text(
        "# YOLO dataset rendered and labelled by `ocslam dataset` (see docs/detector.md)\n" + yaml.safe_dump(data, sort_keys=False)
    )
    meta["class_counts"] = counts
    return meta


def command_line(argv: Sequence[str] | None = None) -> str:
    argv = list(sys.argv[1:] if argv is None else argv)
    return "ocslam " + " ".join(shlex.quote(a) for a in argv)
