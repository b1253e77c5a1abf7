"""Render an auto-labelled YOLO dataset from random worlds and the paper's apartment (split by world).

    ocslam dataset --worlds 40 --per-world 45 --seed 1 --out datasets/sim [--workers 2] [--imgsz 320x240]

World i is random_world(1000·seed + i) of family i mod len(--families) (default all four); a seeded share of them (--val-fraction) is the validation split,
the apartment is training data. Labels are the tight boxes of each object's visible pixels, kept when
at least --min-pixels are visible and at least --min-visible of the object (see docs/detector.md).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--worlds", type=int, default=40, help="random worlds")
    p.add_argument("--per-world", type=int, default=45, help="images per random world")
    p.add_argument("--seed", type=int, default=1, help="dataset seed (world i is random_world(1000·seed + i))")
    p.add_argument("--out", type=Path, required=True, help="output folder (e.g. datasets/sim)")
    p.add_argument("--workers", type=int, default=2, help="rendering processes")
    p.add_argument("--imgsz", default="320x240", help="render size W×H")
    p.add_argument("--val-fraction", type=float, default=0.15, help="share of random worlds used for validation")
    p.add_argument("--no-apartment", action="store_true", help="leave out the paper's apartment")
    p.add_argument("--apartment-images", type=int, default=None, help="images of the apartment (default 2 × per-world)")
    p.add_argument(
        "--min-pixels", type=float, default=30.0, help="label only objects with this many visible pixels (in the image scaled to 224 px wide)"
    )
    p.add_argument("--min-visible", type=float, default=0.35, help="label only objects at least this fraction visible")
    p.add_argument(
        "--min-in-frame", type=float, default=0.5, help="label only objects with at least this fraction inside the frame"
    )
    p.add_argument(
        "--min-box", type=float, default=8.0, help="label only boxes whose shorter side is this long (px, image scaled to 224 px wide)"
    )
    p.add_argument(
        "--families",
        default="rooms,corridor,lshape,openplan",
        help="random_world layout families, comma-separated; world i is of family i mod their number "
        "(default: all four; 'rooms' is the recipe before 2026-12-03)",
    )
    p.add_argument(
        "--renderer",
        choices=("tiny", "egl", "auto"),
        default=None,
        help="camera renderer: tiny (TinyRenderer, the committed models' data; default, or OCSLAM_RENDERER), egl (the "
        "app's renderer where it loads, Mesa's llvmpipe), auto (egl where it loads)",
    )
    p.add_argument(
        "--close-views",
        type=float,
        default=0.0,
        help="share of views taken under an object's top (between a table's legs) or at most 0.3 m from its edge, "
        "so it overflows the frame (default 0: the recipe before 2026-12-05)",
    )
    p.add_argument("--no-randomize", action="store_true", help="no domain randomisation (plain renders)")
    p.add_argument(
        "--compress-images",
        action="store_true",
        help="compressed PNG images (about 60 %% of the size, 2 ms more an image; default: PNG stored uncompressed, "
        "the same pixels)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    from app.training.dataset import DatasetOptions, build_dataset, command_line, parse_imgsz
    from app.training.labels import LabelFilter

    if args.worlds < 0 or args.per_world < 1:
        print("ocslam: error: dataset: --worlds must be ≥ 0 and --per-world ≥ 1", file=sys.stderr)
        return 2
    if not all(0.0 <= v <= 1.0 for v in (args.val_fraction, args.min_visible, args.close_views)):
        print("ocslam: error: dataset: --val-fraction, --min-visible and --close-views must be in [0, 1]", file=sys.stderr)
        return 2
    from app.training.dataset import ALL_FAMILIES

    families = tuple(f.strip() for f in str(args.families).split(",") if f.strip())
    unknown = [f for f in families if f not in ALL_FAMILIES]
    if not families or unknown:
        print(f"ocslam: error: dataset: --families must name some of {', '.join(ALL_FAMILIES)}"
              + (f" (unknown: {', '.join(unknown)})" if unknown else ""), file=sys.stderr)
        return 2
    try:
        imgsz = parse_imgsz(args.imgsz)
    except ValueError as e:
        print(f"ocslam: error: dataset: {e}", file=sys.stderr)
        return 2
    extra = {"renderer": args.renderer} if args.renderer else {}
    if args.renderer == "egl":
        import threading

        from app.sim.renderer import RendererError, resolve_renderer
        from app.training.dataset import preload_worker_modules

        # the workers' modules are imported while the probe's process loads the plugin (it waits, not us)
        preload = threading.Thread(target=preload_worker_modules, name="preload", daemon=True)
        preload.start()
        try:
            resolve_renderer("egl")
        except RendererError as e:
            print(f"ocslam: error: dataset: {e}", file=sys.stderr)
            return 2
        finally:
            preload.join()
    opts = DatasetOptions(
        out=args.out,
        worlds=args.worlds,
        per_world=args.per_world,
        seed=args.seed,
        imgsz=imgsz,
        workers=max(1, args.workers),
        val_fraction=args.val_fraction,
        apartment=not args.no_apartment,
        apartment_images=args.apartment_images,
        label_filter=LabelFilter(args.min_pixels, args.min_visible, args.min_box, min_in_frame_fraction=args.min_in_frame),
        randomize=not args.no_randomize,
        compress_images=args.compress_images,
        close_views=args.close_views,
        families=families,
        command=command_line(),
        **extra,
    )
    import signal

    from app.training.dataset import DatasetError

    def _stop(signum, frame):  # SIGTERM (e.g. kill of a background run) stops the worker processes too
        raise KeyboardInterrupt

    old = signal.signal(signal.SIGTERM, _stop)  # the workers reset it to the default (app.training.dataset._init_worker)
    try:
        meta = build_dataset(opts, progress=not args.quiet)
    except DatasetError as e:
        print(f"ocslam: error: {e}", file=sys.stderr)
        return 2
    finally:
        signal.signal(signal.SIGTERM, old)
    print(
        f"wrote {args.out}: {meta['images']['train']} train / {meta['images']['val']} val images, "
        f"{meta['boxes']['train']} / {meta['boxes']['val']} boxes, "
        f"{len(meta['train_worlds'])} / {len(meta['val_worlds'])} worlds, {meta['render_s']:.0f} s"
    )
    for split in ("train", "val"):
        print(f"  {split}: " + ", ".join(f"{k} {v}" for k, v in meta["class_counts"][split].items()))
    return 0
