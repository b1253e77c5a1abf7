"""Render the detector test images (run from the repo root: .venv/bin/python tests/data/detector/make_images.py tests/data/detector).

One clear view per class, found by trying viewpoints around each object of the apartment (then held-out
random worlds), from its front half (within ±69° of the direction it faces), until the object is a kept label at least 90 % visible with a box side of 18 px or more.
No domain randomisation, no sensor noise. Boxes in expected.yaml are every kept label of the image.
"""
import math
import sys
from pathlib import Path

import cv2
import numpy as np
import yaml

from app.config import Config, resolve_path
from app.ocslam.messages import CLASS_INDEX, CLASS_NAMES
from app.ocslam.se2 import Pose2
from app.sim_world import SimWorld
from app.training.labels import LabelFilter, make_labels
from app.training.silhouettes import SilhouetteRenderer
from app.world.format import load_world
from app.world.generator import random_world

out = Path(sys.argv[1])
out.mkdir(parents=True, exist_ok=True)
W, H = 320, 240
wanted = list(CLASS_NAMES)
found = {}
entries = []
rng = np.random.default_rng(2024)
worlds = [("apartment", load_world(resolve_path("assets/worlds/apartment.yaml")))] + [(f"random_world({s})", random_world(s)) for s in (777001, 777002, 777003)]
for wname, world in worlds:
    with SimWorld(world, Config(), seed=0) as sim, SilhouetteRenderer(world) as sil:
        class_of = {i: CLASS_INDEX[o.label] for i, o in enumerate(world.objects)}
        for oid, o in enumerate(world.objects):
            if o.label in found:
                continue
            for _ in range(80):
                d = rng.uniform(0.6, 2.8)
                a = o.yaw + rng.uniform(-1.2, 1.2)  # from the object's front half (models face +x)
                x, y = o.x + d * math.cos(a), o.y + d * math.sin(a)
                if not sim.pose_free(x, y):
                    continue
                pose = Pose2(x, y, math.atan2(o.y - y, o.x - x))
                fr = sim.render_view(pose, width=W, height=H, segmentation=True)
                vis = [i for i in np.unique(fr.segmentation) if i >= 0]
                full = sil.counts(fr.T_world_camera, fr.info.K, W, H, vis)
                labels = make_labels(fr.segmentation, class_of, full, LabelFilter())
                tgt = [lb for lb in labels if lb.object_id == oid and lb.keep and lb.visible_fraction > 0.9 and min(lb.width, lb.height) >= 18]
                if not tgt:
                    continue
                name = f"{o.label}.png"
                cv2.imwrite(str(out / name), fr.image.data[:, :, ::-1])
                entries.append({"image": name, "world": wname, "pose": [round(x, 3), round(y, 3), round(pose.yaw, 4)],
                                "objects": [{"class": CLASS_NAMES[lb.class_id], "box": [lb.x1, lb.y1, lb.x2, lb.y2], "visible_fraction": round(lb.visible_fraction, 3)}
                                            for lb in labels if lb.keep]})
                found[o.label] = name
                break
print(sorted(found), set(wanted) - set(found))
(out / "expected.yaml").write_text("# Rendered by tests/data/detector/make_images.py; boxes: x1, y1, x2, y2 (px, 320x240)\n" + yaml.safe_dump(entries, sort_keys=False))
