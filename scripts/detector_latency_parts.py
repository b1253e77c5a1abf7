"""Where one detector frame's time goes: letterbox, ``session.run``, decode + NMS, and the whole ``detect``, on a
rendered 320×240 apartment frame with the app's model, median of 200 (``ocslam bench detector`` gives the totals).

    python scripts/detector_latency_parts.py [THREADS=2]
"""
import sys
import time

import numpy as np

from app.config import Config, resolve_path
from app.ocslam.detector import Detector, decode_output, letterbox
from app.sim_world import SimWorld
from app.world.format import load_world

cfg = Config()
cfg.detector.threads = int(sys.argv[1]) if len(sys.argv) > 1 else 2
det = Detector(cfg.detector, resolve_path(cfg.detector.model_path))
sim = SimWorld(load_world(resolve_path(cfg.sim.world)), cfg, seed=0)
img = sim.render_camera(320, 240).image
sim.close()
for _ in range(20):
    det.detect(img)
parts: dict[str, list[float]] = {"letterbox": [], "session.run": [], "decode": [], "detect": []}
for _ in range(200):
    t0 = time.perf_counter()
    blob, lb = letterbox(img.data, det._blob.shape[3], det._blob.shape[2], out=det._blob)
    t1 = time.perf_counter()
    out = det.session.run(None, {det._input_name: blob})[0]
    t2 = time.perf_counter()
    decode_output(out, det.num_classes, float(cfg.detector.confidence), float(cfg.detector.nms_iou), lb, 320, 240)
    t3 = time.perf_counter()
    det.detect(img)
    t4 = time.perf_counter()
    for k, a, b in (("letterbox", t0, t1), ("session.run", t1, t2), ("decode", t2, t3), ("detect", t3, t4)):
        parts[k].append((b - a) * 1e3)
print(f"threads {cfg.detector.threads}, input {tuple(det._blob.shape)}: "
      + ", ".join(f"{k} {np.median(v):.2f} ms" for k, v in parts.items()))
