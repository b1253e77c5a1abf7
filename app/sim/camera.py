"""The robot's camera in a pybullet client: one rendered frame (RGB, depth, segmentation) and its noise.

The renderer is pybullet's EGL plugin or TinyRenderer (:mod:`app.sim.renderer` chooses). A frame is drawn
from a ``(4, 4)`` pose of the optical frame (REP-103 optical: z forward, x right, y down) with ideal
pinhole intrinsics from the horizontal FOV (``camera.hfov_rad``), lit by ``sim.light_*``; the depth buffer
becomes metres along the optical axis, the segmentation ground-truth object ids.
"""

from __future__ import annotations

import contextlib
import math
import threading
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.ocslam.messages import CameraInfo, Image
from app.sim.egl_shadow import ShadowMapSwitch
from app.sim.renderer import RendererError, quiet_c_stdout

__all__ = ["Camera", "CameraFrame", "PixelNoise", "camera_size"]


@dataclass
class CameraFrame:
    """One rendered image with its intrinsics and (optionally) ground-truth depth and segmentation.

    ``depth``: ``(H, W)`` float32 metres along the optical z axis. ``segmentation``: ``(H, W)`` int32,
    the :class:`GroundTruthObject` id seen in each pixel, -1 for background and unclassified geometry.
    ``T_world_camera``: ``(4, 4)`` pose of the optical frame in the world (ground truth).
    """

    stamp: float
    image: Image
    info: CameraInfo
    depth: NDArray[np.float32] | None = None
    segmentation: NDArray[np.int32] | None = None
    T_world_camera: NDArray[np.float64] | None = None


def camera_size(c: Any) -> tuple[int, int]:
    """The default render size for the ``camera`` config section ``c``: ``render_width`` (aspect kept) or
    the full ``width × height``."""
    if c.render_width and c.render_width < c.width:
        w = int(c.render_width)
        return w, max(1, int(round(c.height * w / c.width)))
    return int(c.width), int(c.height)


class Camera:
    """Renders frames in pybullet client ``client`` with ``renderer`` (``"egl"`` or ``"tiny"``).

    ``seg_lut``: body id → ground-truth object id (-1 otherwise). ``gl_thread``: the thread that holds
    the EGL context (None for TinyRenderer): a render from any other thread is refused with
    :class:`RendererError` (it would crash the process). ``shadow_switch``
    (:class:`~app.sim.egl_shadow.ShadowMapSwitch`, EGL only) is set to ``shadow_map`` before each frame
    (the plugin's flag is per process, and other clients may want the other setting).
    """

    def __init__(self, p: Any, client: int, *, renderer: str, seg_lut: NDArray[np.int32], gl_thread: int | None,
                 shadow_switch: ShadowMapSwitch | None = None, shadow_map: bool = False) -> None:
        self._p = p
        self.shadow_switch = shadow_switch
        self.shadow_map = shadow_map
        self.client = client
        self.renderer = renderer
        self.renderer_flag = p.ER_BULLET_HARDWARE_OPENGL if renderer == "egl" else p.ER_TINY_RENDERER
        self.seg_lut = seg_lut
        self.gl_thread = gl_thread

    def render(
        self,
        T_world_cam: NDArray[np.float64],
        width: int,
        height: int,
        *,
        camera: Any,
        sim: Any,
        stamp: float,
        depth: bool,
        segmentation: bool,
        light: dict | None = None,
    ) -> CameraFrame:
        """A frame from the optical frame's pose ``T_world_cam`` ``(4, 4)``; ``camera`` and ``sim``: the
        config sections (FOV, clipping planes, lighting); ``light`` overrides pybullet's light arguments."""
        p, cid = self._p, self.client
        if self.gl_thread is not None and threading.get_ident() != self.gl_thread:
            raise RendererError(
                "the EGL renderer draws only on the thread that built this world; "
                "build it on the rendering thread or use sim.renderer=tiny"
            )
        cc = camera
        info = CameraInfo.from_fov(width, height, cc.hfov_rad)
        eye = T_world_cam[:3, 3]
        z_axis, y_axis = T_world_cam[:3, 2], T_world_cam[:3, 1]
        view = p.computeViewMatrix(eye.tolist(), (eye + z_axis).tolist(), (-y_axis).tolist(), physicsClientId=cid)
        fov_y = math.degrees(2.0 * math.atan((height / 2.0) / info.K[1, 1]))
        near, far = float(cc.near_m), float(cc.far_m)
        proj = p.computeProjectionMatrixFOV(fov_y, width / height, near, far, physicsClientId=cid)
        try:
            light_dir = [float(v) for v in sim.light_direction]
            if len(light_dir) != 3 or not all(math.isfinite(v) for v in light_dir):
                raise ValueError
        except (TypeError, ValueError):
            light_dir = [0.3, -0.4, 1.0]  # a malformed sim.light_direction must not stop the camera
        kw: dict[str, Any] = dict(
            lightDirection=light_dir,
            lightAmbientCoeff=float(sim.light_ambient),
            lightDiffuseCoeff=float(sim.light_diffuse),
            shadow=0,
        )
        if light:
            kw.update(light)
        flags = 0 if segmentation else p.ER_NO_SEGMENTATION_MASK
        if self.shadow_switch is not None:
            self.shadow_switch.set(self.shadow_map)
        with quiet_c_stdout() if self.renderer == "egl" else contextlib.nullcontext():
            _, _, rgba, zbuf, seg = p.getCameraImage(
                width, height, view, proj, renderer=self.renderer_flag, flags=flags, physicsClientId=cid, **kw
            )
        rgb = np.ascontiguousarray(np.reshape(np.asarray(rgba, dtype=np.uint8), (height, width, 4))[:, :, :3])
        frame = CameraFrame(stamp=stamp, image=Image(stamp=stamp, data=rgb), info=info, T_world_camera=T_world_cam)
        if depth:
            d = np.reshape(np.asarray(zbuf, dtype=np.float64), (height, width))
            frame.depth = (far * near / (far - (far - near) * d)).astype(np.float32)
        if segmentation:
            s = np.reshape(np.asarray(seg, dtype=np.int64), (height, width))
            out = np.full(s.shape, -1, dtype=np.int32)
            ok = (s >= 0) & (s < len(self.seg_lut))
            out[ok] = self.seg_lut[s[ok]]
            frame.segmentation = out
        return frame


class PixelNoise:
    """Gaussian pixel noise σ (0–255), cheaply: a random window of a per-size noise bank (drawing ~10⁶
    normals per 640×480 frame would cost more than half a render). ``rng``: the camera's noise stream."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self._banks: dict[tuple, NDArray[np.int16]] = {}

    def add(self, rgb: NDArray[np.uint8], sigma: float) -> NDArray[np.uint8]:
        """``rgb`` ``(H, W, 3)`` uint8 with noise added (a new array)."""
        h, w, _ = rgb.shape
        key = (h, w, sigma)
        bank = self._banks.get(key)
        if bank is None:
            bank = np.round(self.rng.normal(0.0, sigma, (h + 61, w + 67, 3))).astype(np.int16)
            self._banks = {key: bank}
        dy = int(self.rng.integers(0, bank.shape[0] - h + 1))
        dx = int(self.rng.integers(0, bank.shape[1] - w + 1))
        out = rgb.astype(np.int16)
        out += bank[dy : dy + h, dx : dx + w]
        return np.clip(out, 0, 255).astype(np.uint8)
