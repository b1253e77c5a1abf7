"""Camera render time per frame in the apartment, EGL with and without the plugin's shadow-map pass
(``sim.egl_shadow_map``), alternating in one process: median of 20 frames per size, two rounds.

    python scripts/render_time.py          # rows: (shadow map, width, segmentation) → ms per round
"""
import time

import numpy as np

from app.config import Config, resolve_path
from app.sim_world import SimWorld
from app.world.format import load_world

cfg = Config.load(None, ["camera.noise_std=0", "sim.renderer=egl"])
sim = SimWorld(load_world(resolve_path(cfg.sim.world)), cfg, seed=0)
res: dict[tuple, list[float]] = {}
for _round in range(2):
    for shadow in (True, False):
        sim._camera.shadow_map = shadow
        for w, h in [(64, 48), (320, 240), (640, 480)]:
            for seg in (False, True):
                sim.render_camera(w, h, segmentation=seg)
                ts = []
                for _ in range(20):
                    t = time.perf_counter()
                    sim.render_camera(w, h, segmentation=seg)
                    ts.append(time.perf_counter() - t)
                res.setdefault((shadow, f"{w}x{h}", seg), []).append(float(np.median(ts)) * 1e3)
sim.close()
for (shadow, size, seg), v in sorted(res.items()):
    print(f"shadow map {shadow!s:5} {size:8} segmentation {seg!s:5} " + " / ".join(f"{x:.1f} ms" for x in v))
