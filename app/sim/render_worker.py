"""Camera rendering in a separate process, so it overlaps with SLAM and the detector on the other core.

Rendering (pybullet's EGL plugin on Mesa's llvmpipe, or TinyRenderer) is pixel fill on the CPU: 5 ms a
320×240 frame with EGL without its shadow-map pass (app/sim/egl_shadow.py), 15–25 ms with TinyRenderer.
:class:`CameraWorker` keeps a second pybullet client with the same world in a child process. The loop
*requests* a frame at its stamp with the robot's true pose and *collects* it a fixed sim-time latency later
(``camera.latency_s``, like a real camera driver's), blocking only if the worker is late. Frames are therefore
processed at the same sim step whatever the machine's load: runs stay deterministic.

    worker = CameraWorker(world, cfg)
    worker.request(stamp, T_world_base, width=224, height=168)
    ...                                   # physics, LIDAR, SLAM run meanwhile
    frame = worker.collect()              # CameraFrame (stamp = the request's)
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import os
import traceback
from collections import deque
from dataclasses import dataclass
from typing import Any

from app.ocslam.se2 import Pose2

log = logging.getLogger(__name__)


class CameraWorkerError(RuntimeError):
    """The render process died or answered with an error."""


@dataclass(frozen=True)
class _Request:
    stamp: float
    pose: tuple[float, float, float]
    width: int
    height: int
    segmentation: bool


def _worker_main(conn: Any, world: Any, cfg: Any, seed: int, warmup: tuple[int, int] | None = None) -> None:
    """Child process: a SimWorld that only renders. Its C-level stdout goes to /dev/null (the EGL plugin
    prints at every frame); the first frame (shader compilation, ~0.5 s) is rendered before "ready"."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)
        os.close(devnull)
    except OSError:
        pass
    try:
        from app.sim_world import SimWorld

        sim = SimWorld(world, cfg, seed=seed)
        if warmup is not None:
            sim.render_camera(*warmup)
    except BaseException:  # noqa: BLE001
        conn.send(("error", traceback.format_exc()))
        return
    conn.send(("ready", {"renderer": sim.renderer, "renderer_note": sim.renderer_note}))
    while True:
        try:
            req = conn.recv()
        except (EOFError, OSError):
            break
        if req is None:
            break
        try:
            sim.set_robot_pose(Pose2(*req.pose))
            sim.time = req.stamp
            frame = sim.render_camera(req.width, req.height, segmentation=req.segmentation)
            conn.send(("frame", frame))
        except BaseException:  # noqa: BLE001
            conn.send(("error", traceback.format_exc()))
    sim.close()


class CameraWorker:
    """A render process with its own copy of the world (see the module docstring)."""

    #: pybullet's TinyRenderer never returns for a few exact camera poses (seen: one pose of a random
    #: world; 1 mm away it renders in 20 ms). A late frame restarts the process and the pose is nudged.
    JITTER_M = 2e-4

    def __init__(self, world: Any, cfg: Any, seed: int = 0, *, start_timeout_s: float = 120.0,
                 frame_timeout_s: float = 15.0, warmup: tuple[int, int] | None = None) -> None:
        """``warmup``: a ``(width, height)`` frame rendered (and dropped) before the worker reports ready.
        :attr:`renderer` / :attr:`renderer_note`: what the process renders with (``"egl"`` or ``"tiny"``)."""
        from app.sim.renderer import resolve_renderer

        # probes EGL once here (the verdict reaches the child through the environment); a forced but
        # unavailable EGL fails here, with the reason
        resolve_renderer(getattr(cfg.sim, "renderer", "auto"))
        self._args = (world, cfg, seed, warmup)
        self.renderer = "tiny"
        self.renderer_note = ""
        self.start_timeout_s = start_timeout_s
        self.frame_timeout_s = frame_timeout_s
        self._pending: deque[_Request] = deque()
        self.restarts = 0
        self._start()

    def _start(self) -> None:
        ctx = mp.get_context("spawn")  # never fork a process that holds a pybullet client
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(target=_worker_main, args=(child, *self._args), daemon=True, name="ocslam-camera")
        self._proc.start()
        child.close()
        if not self._conn.poll(self.start_timeout_s):
            self.close()
            raise CameraWorkerError("the camera render process did not start")
        kind, payload = self._conn.recv()
        if kind != "ready":
            self.close()
            raise CameraWorkerError(f"the camera render process failed to start:\n{payload}")
        if isinstance(payload, dict):
            self.renderer = str(payload.get("renderer", "tiny"))
            self.renderer_note = str(payload.get("renderer_note", ""))

    def _restart(self, why: str = "stuck") -> None:
        """Kill a stuck (or dead) render process, start a new one and re-send what was pending (the first
        nudged)."""
        log.warning("camera render process %s on %s: restarting it", why, self._pending[0] if self._pending else None)
        self._proc.kill()
        self._proc.join(timeout=5)
        self._conn.close()
        self.restarts += 1
        self._start()
        pending = list(self._pending)
        if pending:
            r = pending[0]
            pending[0] = _Request(r.stamp, (r.pose[0] + self.JITTER_M, r.pose[1] + self.JITTER_M, r.pose[2]),
                                  r.width, r.height, r.segmentation)
        self._pending = deque(pending)
        for r in pending:
            self._conn.send(r)

    @property
    def pending(self) -> int:
        return len(self._pending)

    def oldest_stamp(self) -> float | None:
        return self._pending[0].stamp if self._pending else None

    def request(self, stamp: float, T_world_base: Pose2, *, width: int, height: int, segmentation: bool = False) -> None:
        req = _Request(float(stamp), (T_world_base.x, T_world_base.y, T_world_base.yaw), int(width), int(height),
                       bool(segmentation))
        self._pending.append(req)
        try:
            self._conn.send(req)
        except OSError:  # the process died (a native crash in the renderer): a new one gets every pending request
            self._restart(f"died (exit code {self._proc.exitcode})")

    def collect(self, timeout_s: float | None = None):
        """The oldest requested frame (blocks until it is rendered). A render process that is stuck, or that
        died (a native crash in the renderer), is replaced and the frame asked again, once; twice in a row,
        the frame is dropped with a :class:`CameraWorkerError` (the process is replaced again for the next)."""
        if not self._pending:
            raise CameraWorkerError("collect() without a pending request")
        timeout_s = self.frame_timeout_s if timeout_s is None else timeout_s
        for attempt in range(2):
            if self._conn.poll(timeout_s):
                try:
                    kind, payload = self._conn.recv()
                except (EOFError, OSError):
                    why = f"died (exit code {self._proc.exitcode})"
                else:
                    self._pending.popleft()
                    if kind != "frame":
                        raise CameraWorkerError(f"render failed:\n{payload}")
                    return payload
            else:
                why = f"stuck for {timeout_s:.0f} s"
            if attempt == 0:
                self._restart(why)
        lost = self._pending.popleft()
        self._restart(why)
        raise CameraWorkerError(f"no frame from the render process ({why}, twice): {lost}")

    def close(self) -> None:
        try:
            if self._proc.is_alive():
                self._conn.send(None)
                self._proc.join(timeout=5)
        except (OSError, BrokenPipeError):
            pass
        if self._proc.is_alive():
            self._proc.terminate()
            self._proc.join(timeout=5)
        self._conn.close()

    def __del__(self) -> None:  # pragma: no cover - best effort
        try:
            self.close()
        except Exception:
            pass
