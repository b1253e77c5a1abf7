"""mAP of the committed detector on EGL vs TinyRenderer renders of the same scenes (same poses), with
app/bench/detector.py's machinery (Sample, GtBox, run_detector, coco_evaluate). Ground truth from each
render's own segmentation (objects >= 400 px at 640x480, the same share of the image at other sizes;
smaller ones are ignore regions). Three renders of each pose: TinyRenderer, EGL with pybullet's
shadow-map pass (``sim.egl_shadow_map = true``) and EGL without it (the default).

    python scripts/map_egl_tiny.py [POSES_PER_WORLD=20] [RANDOM_WORLDS=3] [WxH=640x480]   # JSON on stdout
"""
import json
import math
import sys
import time

import numpy as np

from app.bench.detector import coco_evaluate, run_detector
from app.config import Config, resolve_path
from app.ocslam.detector import Detector
from app.ocslam.messages import CLASS_INDEX
from app.ocslam.se2 import Pose2
from app.sim_world import SimWorld
from app.training.labels import visible_boxes
from app.training.samples import GtBox, Sample
from app.world.format import load_world
from app.world.generator import random_world

PER_WORLD = int(sys.argv[1]) if len(sys.argv) > 1 else 20
N_RANDOM = int(sys.argv[2]) if len(sys.argv) > 2 else 3
W, H = (int(v) for v in (sys.argv[3] if len(sys.argv) > 3 else "640x480").split("x"))
MIN_PX = 400 * W * H / (640 * 480)
VARIANTS = {"tiny": ("tiny", True), "egl_shadow_map": ("egl", True), "egl": ("egl", False)}  # renderer, shadow map
cfg = Config.load(None, ["camera.noise_std=0"])
worlds = [load_world(resolve_path(cfg.sim.world))] + [random_world(99000 + i) for i in range(N_RANDOM)]
samples: dict = {k: [] for k in VARIANTS}
t0 = time.time()
for wi, world in enumerate(worlds):
    rng = np.random.default_rng(1234 + wi)
    sims = {r: SimWorld(world, cfg, seed=0, renderer=r) for r in ("tiny", "egl")}  # one EGL client per process
    ref = sims["tiny"]
    xmin, ymin, xmax, ymax = world.bounds()
    k = tries = 0
    while k < PER_WORLD and tries < PER_WORLD * 50:
        tries += 1
        x, y = rng.uniform(xmin, xmax), rng.uniform(ymin, ymax)
        if not ref.pose_free(x, y):
            continue
        o = world.objects[int(rng.integers(len(world.objects)))]
        d = math.hypot(o.x - x, o.y - y)
        if not 0.8 < d < 3.5:
            continue
        yaw = math.atan2(o.y - y, o.x - x) + rng.uniform(-0.35, 0.35)
        T = Pose2(x, y, yaw)
        for r, (renderer, shadow) in VARIANTS.items():
            sim = sims[renderer]
            sim._camera.shadow_map = shadow
            f = sim.render_view(T, width=W, height=H, segmentation=True)
            boxes = []
            for oid, (x1, y1, x2, y2, n) in visible_boxes(f.segmentation).items():
                if 0 <= oid < len(world.objects):
                    boxes.append(GtBox(CLASS_INDEX[world.objects[oid].label], x1, y1, x2, y2, ignore=n < MIN_PX))
            samples[r].append(Sample(None, W, H, tuple(boxes), rgb=f.image.data))
        k += 1
    for s in sims.values():
        s.close()
print(f"rendered {len(samples['tiny'])} poses in {time.time() - t0:.0f} s", file=sys.stderr)
det = Detector(cfg.detector, resolve_path(cfg.detector.model_path))
out = {}
for r, ss in samples.items():
    res = coco_evaluate(ss, run_detector(det, ss), float(cfg.detector.confidence))
    out[r] = {k: res[k] for k in ("images", "instances", "map50", "map50_95", "precision", "recall")}
    out[r]["per_class_ap50"] = {c: round(v["ap50"], 3) for c, v in res["per_class"].items() if v["instances"]}
print(json.dumps({"worlds": ["apartment"] + [f"random_world({99000 + i})" for i in range(N_RANDOM)],
                  "per_world": PER_WORLD, "size": [W, H], "model": str(det.model_path), **out}, indent=1))
