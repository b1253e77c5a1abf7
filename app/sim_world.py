"""The simulated TurtleBot3 Burger in a world: pybullet geometry, kinematic drive, sensors, ground truth.

Design (measured choices, see ``ocslam bench sim``):

- **Geometry** lives in a private pybullet DIRECT client: one static body per model part, walls as
  boxes with their openings cut out, a floor, and the robot loaded from its URDF (moved kinematically).
- **Motion** is kinematic, not dynamic: each fixed step the commanded wheel rates (``cmd_vel`` through
  :func:`twist_to_wheel_rates`, so ``robot.odometry_mode = "seed"`` reproduces the original's turn-rate
  bug physically) pass a first-order motor lag; the wheels turn by ``ω·dt`` (what the encoders measure)
  while the ground sees ``r·ω·(1 − slip)`` with a slowly varying per-wheel slip (and an optional per-run
  wheel-radius error). The pose integrates exactly along the arc. A step that would put the robot's
  collision cylinder (radius ``robot.footprint_radius_m``, ``sim.robot_height_m`` tall) into anything is
  refused (the robot stalls, its wheels slip), so it never passes through walls or objects. Deterministic
  for a seed; no contact dynamics to tune or to explode.
- **LIDAR**: from the ``base_scan`` frame of the URDF, rays cast in 2D against the exact cross-section of
  every collision shape at the LIDAR's height (:class:`PlanarCaster`, ``lidar.caster = planar``; the
  world is static), or one pybullet ``rayTestBatch`` (``lidar.caster = pybullet``); **camera**: pybullet's EGL
  renderer plugin (OpenGL; Mesa's llvmpipe without a GPU) where it loads, else TinyRenderer
  (``sim.renderer``: ``auto | egl | tiny``), from ``camera_optical_frame``, with depth and a segmentation
  of ground-truth object ids. The EGL plugin is first probed in a child process (a broken EGL stack
  exits the process that loads it), once per process tree.

Every message is stamped with sim time (``SimWorld.time``). All noise comes from seeded
``numpy.random.Generator`` streams (one per source). Ground truth (:meth:`true_pose`, :meth:`ground_truth_objects`, ...) is for
evaluation and overlays only.

Example:
    >>> sim = SimWorld(load_world("assets/worlds/apartment.yaml"), Config())
    >>> sim.set_cmd_vel(Twist(0.2, 0.0)); sim.step(100)                 # 1 s forward
    >>> scan, frame = sim.scan(), sim.render_camera(320, 240, segmentation=True)
    >>> sim.close()
"""

from __future__ import annotations

import contextlib
import ctypes
import importlib.util
import json
import logging
import math
import os
import subprocess
import sys
import threading
from dataclasses import dataclass
from typing import Any, Iterator, Sequence

import numpy as np
from numpy.typing import NDArray

from app.config import Config
from app.ocslam.messages import CameraInfo, GroundTruthObject, GroundTruthObstacle, Image, LaserScan, Twist, WheelEncoders
from app.ocslam.odometry import twist_to_wheel_rates
from app.ocslam.se2 import Pose2, wrap_angle
from app.sim.robot_model import RobotModel
from app.world_models import build_model_pybullet, get_model, resolve_colors
from app.worlds import World

__all__ = ["CameraFrame", "RENDERERS", "RendererError", "SimWorld", "pose3", "probe_egl", "resolve_renderer"]

log = logging.getLogger(__name__)

# collision filter groups: rays and the robot's collision query only see WORLD bodies
_G_WORLD, _G_ROBOT, _G_FLOOR, _G_CHECK = 1, 2, 4, 8
_GLASS = (0.62, 0.78, 0.9)
_FAR_AWAY = (0.0, 0.0, -50.0)


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


# ----------------------------------------------------------------------------------------------
# renderer choice
# ----------------------------------------------------------------------------------------------
#: ``sim.renderer`` values: EGL where it loads (auto), EGL or an error (egl), TinyRenderer (tiny)
RENDERERS = ("auto", "egl", "tiny")
#: environment: the EGL plugin's path (default: pybullet's ``eglRenderer`` module); a missing file
#: makes the EGL load fail (the tests' failure case)
EGL_PLUGIN_ENV = "OCSLAM_EGL_PLUGIN"
#: environment: the probe's verdict, passed on to child processes (render worker, dataset pool)
EGL_PROBE_ENV = "OCSLAM_EGL_PROBE"
#: environment: what ``auto`` means in this process and its children (``tiny`` or ``egl``), e.g. to
#: render a dataset or a detector benchmark with one renderer: ``OCSLAM_RENDERER=tiny ocslam dataset ...``
RENDERER_ENV = "OCSLAM_RENDERER"

_PROBE_CODE = r"""
import sys, pybullet as p
cid = p.connect(p.DIRECT)
if p.loadPlugin(sys.argv[1], "_eglRendererPlugin", physicsClientId=cid) < 0:
    print("OCSLAM_PROBE loadPlugin failed", file=sys.stderr); sys.exit(3)
vis = p.createVisualShape(p.GEOM_BOX, halfExtents=[0.2, 0.2, 0.2], rgbaColor=[1, 0, 0, 1], physicsClientId=cid)
p.createMultiBody(0, -1, vis, [1, 0, 0], physicsClientId=cid)
view = p.computeViewMatrix([0, 0, 0], [1, 0, 0], [0, 0, 1])
proj = p.computeProjectionMatrixFOV(60, 4 / 3, 0.05, 20)
_, _, rgba, _, seg = p.getCameraImage(32, 24, view, proj, renderer=p.ER_BULLET_HARDWARE_OPENGL, physicsClientId=cid)
import numpy as np
seg = np.reshape(np.asarray(seg), (24, 32))
if seg[12, 16] != 0 or seg[0, 0] != -1:
    print("OCSLAM_PROBE wrong image", file=sys.stderr); sys.exit(4)
print("OCSLAM_PROBE ok", file=sys.stderr)
"""


class RendererError(RuntimeError):
    """The requested renderer cannot be used (``sim.renderer = egl`` where EGL does not load)."""


def egl_plugin_path() -> str | None:
    """The EGL renderer plugin's shared library (``$OCSLAM_EGL_PLUGIN`` or pybullet's ``eglRenderer``)."""
    env = os.environ.get(EGL_PLUGIN_ENV)
    if env:
        return env
    try:
        spec = importlib.util.find_spec("eglRenderer")
    except (ImportError, ValueError):
        return None
    return spec.origin if spec is not None else None


_probe_cache: dict[str, tuple[bool, str]] = {}
_probe_lock = threading.Lock()


def probe_egl(timeout_s: float = 120.0) -> tuple[bool, str]:
    """``(ok, detail)``: can pybullet's EGL plugin render here? Tried once in a child process (a missing
    libEGL or an unusable display makes the plugin exit its process); the verdict is cached for this
    process and passed to child processes through ``$OCSLAM_EGL_PROBE``. ``detail`` names the OpenGL
    renderer (``llvmpipe (LLVM 15.0.6, 256 bits)``) or why EGL failed."""
    path = egl_plugin_path()
    if path is None:
        return False, "pybullet has no eglRenderer plugin"
    with _probe_lock:
        if path in _probe_cache:
            return _probe_cache[path]
        try:
            cached = json.loads(os.environ.get(EGL_PROBE_ENV, "") or "{}")
        except ValueError:
            cached = {}
        if isinstance(cached, dict) and cached.get("plugin") == path and "ok" in cached:
            res = (bool(cached["ok"]), str(cached.get("detail", "")))
        else:
            res = _run_probe(path, timeout_s)
            os.environ[EGL_PROBE_ENV] = json.dumps({"plugin": path, "ok": res[0], "detail": res[1]})
        _probe_cache[path] = res
        return res


def _run_probe(path: str, timeout_s: float) -> tuple[bool, str]:
    if not os.path.exists(path):
        return False, f"EGL plugin {path} does not exist"
    try:
        r = subprocess.run([sys.executable, "-c", _PROBE_CODE, path], capture_output=True, text=True, timeout=timeout_s,
                           env={**os.environ, "OMP_NUM_THREADS": "1"})
    except (OSError, subprocess.TimeoutExpired) as e:
        return False, f"EGL probe failed: {e}"
    gl = next((ln.split("=", 1)[1].strip() for ln in r.stdout.splitlines() if ln.startswith("GL_RENDERER=")), "")
    if r.returncode == 0 and "OCSLAM_PROBE ok" in r.stderr and gl:
        return True, gl
    tail = " ".join((r.stderr.strip().splitlines() or [""])[-2:])
    return False, f"EGL probe exited with {r.returncode}: {tail or 'no output'}"


def resolve_renderer(requested: str) -> tuple[str, str]:
    """``(renderer, note)`` for ``sim.renderer``: ``"egl"`` or ``"tiny"``, and a human-readable note
    (the OpenGL renderer, or why TinyRenderer is used). ``"egl"`` raises :class:`RendererError` if EGL
    cannot render here; ``"auto"`` falls back to TinyRenderer with a logged warning."""
    requested = str(requested or "auto").lower()
    if requested == "auto" and os.environ.get(RENDERER_ENV):
        requested = os.environ[RENDERER_ENV].strip().lower()
    if requested not in RENDERERS:
        raise RendererError(f"unknown renderer {requested!r} (choices: {', '.join(RENDERERS)})")
    if requested == "tiny":
        return "tiny", "TinyRenderer (requested)"
    ok, detail = probe_egl()
    if ok:
        return "egl", f"EGL ({detail})"
    if requested == "egl":
        raise RendererError(f"the EGL renderer does not load: {detail}. {EGL_INSTALL_HINT}")
    msg = f"EGL renderer unavailable ({detail}); using TinyRenderer. {EGL_INSTALL_HINT}"
    if not getattr(resolve_renderer, "_warned", False):
        log.warning("%s", msg)
        resolve_renderer._warned = True  # type: ignore[attr-defined]
    return "tiny", f"TinyRenderer (fallback: {detail})"


EGL_INSTALL_HINT = "Install Mesa's EGL: sudo apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri (or: sudo make setup)."

_devnull_fd: int | None = None
_stdout_lock = threading.Lock()
_libc: Any = None


def _c_fflush() -> None:
    """Flush C stdio buffers (what the plugin printed must reach /dev/null, not the restored stdout)."""
    global _libc
    try:
        if _libc is None:
            _libc = ctypes.CDLL(None)
        _libc.fflush(None)
    except Exception:
        pass


_alias_root: str | None = None
_aliases: dict[tuple[str, tuple[float, ...]], str] = {}


def egl_mesh_alias(path: str, mesh_scale: Sequence[float]) -> str:
    """A file name for ``path`` unique to ``mesh_scale``: pybullet's EGL renderer caches meshes by file
    name, so two scales of one file (a table's top and legs) would both be drawn at the first scale.
    The alias is a per-process symlink to the mesh's *directory* (its .mtl and textures resolve)."""
    global _alias_root
    key = (os.path.abspath(path), tuple(round(float(v), 9) for v in mesh_scale))
    got = _aliases.get(key)
    if got is not None:
        return got
    import atexit
    import hashlib
    import shutil
    import tempfile

    if _alias_root is None:
        _alias_root = tempfile.mkdtemp(prefix="ocslam-egl-meshes-")
        atexit.register(shutil.rmtree, _alias_root, True)
    first = next((k for k in _aliases if k[0] == key[0]), None)
    if first is None:  # the first scale of a file keeps its own name
        _aliases[key] = key[0]
        return key[0]
    d = os.path.join(_alias_root, hashlib.sha1(repr(key).encode()).hexdigest()[:16])
    if not os.path.exists(d):
        os.symlink(os.path.dirname(key[0]), d)
    _aliases[key] = os.path.join(d, os.path.basename(key[0]))
    return _aliases[key]


@contextlib.contextmanager
def quiet_c_stdout(stderr: bool = False) -> Iterator[None]:
    """Silence what C code writes to file descriptor 1 (and 2 if ``stderr``): pybullet's EGL plugin prints
    its OpenGL strings at load and ``ven = Mesa/X.org`` at every render, which would corrupt ``--json``."""
    global _devnull_fd
    fds = (1, 2) if stderr else (1,)
    with _stdout_lock:
        for s in (sys.stdout, sys.stderr):
            try:
                s.flush()
            except Exception:
                pass
        if _devnull_fd is None:
            _devnull_fd = os.open(os.devnull, os.O_WRONLY)
        saved = [os.dup(fd) for fd in fds]
        try:
            for fd in fds:
                os.dup2(_devnull_fd, fd)
            yield
        finally:
            _c_fflush()
            for fd, s in zip(fds, saved):
                os.dup2(s, fd)
                os.close(s)


class PlanarCaster:
    """The LIDAR's plane cut through the world's collision shapes, and rays cast against it in 2D.

    The LIDAR stays at one height above a flat floor, so what its rays can meet is a fixed set of 2D
    outlines: the cross-section of every world body's collision shape (pybullet's own: boxes, convex
    hulls of meshes, cylinders, spheres and capsules as 64-sided polytopes, tilted ones included) at
    ``z``. Each cross-section is the convex hull of the shape's vertex-pair segments cut by the plane.
    A scan casts its rays against those outlines' edges, each edge only against the rays inside its
    angular span (a few thousand ray–edge pairs instead of pybullet's 3D ray test of every ray).
    """

    N_ROUND = 64

    def __init__(self, p: Any, client: int, bodies: Sequence[int], z: float) -> None:
        self.z = float(z)
        segs: list[NDArray[np.float64]] = []
        self.polygons: list[NDArray[np.float64]] = []
        for b in sorted(bodies):
            pos, orn = p.getBasePositionAndOrientation(b, physicsClientId=client)
            lo, hi = p.getAABB(b, -1, physicsClientId=client)
            if not (lo[2] - 1e-6 <= self.z <= hi[2] + 1e-6):
                continue
            for verts in self._shape_vertices(p, client, b, pos, orn):
                poly = self._slice(verts, self.z)
                if poly is not None and len(poly) >= 3:
                    self.polygons.append(poly)
                    segs.append(np.hstack([poly, np.roll(poly, -1, axis=0)]))
        self.segments = np.vstack(segs) if segs else np.zeros((0, 4))
        s = self.segments
        self._p0 = s[:, :2]
        self._e = s[:, 2:] - s[:, :2]

    def _shape_vertices(self, p: Any, client: int, body: int, pos: Any, orn: Any) -> list[NDArray[np.float64]]:
        """World-frame vertices of each convex collision shape of ``body`` (``(K, 3)`` each)."""
        R_body = np.reshape(p.getMatrixFromQuaternion(orn), (3, 3))
        t_body = np.asarray(pos, dtype=np.float64)
        out = []
        shapes = p.getCollisionShapeData(body, -1, physicsClientId=client)
        n_mesh, mesh_v = 0, []
        if any(d[2] == p.GEOM_MESH for d in shapes):  # (getMeshData prints "?" for primitives)
            n_mesh, mesh_v = p.getMeshData(body, -1, physicsClientId=client)
        for d in shapes:
            geom, dims = d[2], d[3]
            R_loc = np.reshape(p.getMatrixFromQuaternion(d[6]), (3, 3))
            t_loc = np.asarray(d[5], dtype=np.float64)
            ring = np.linspace(0.0, 2.0 * math.pi, self.N_ROUND, endpoint=False)
            if geom == p.GEOM_BOX:
                h = np.asarray(dims, dtype=np.float64) / 2.0
                v = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * h
            elif geom in (p.GEOM_CYLINDER, p.GEOM_CAPSULE):
                length, r = float(dims[0]), float(dims[1])
                zs = [-length / 2, length / 2]
                if geom == p.GEOM_CAPSULE:  # hemispherical caps as rings
                    for a in np.linspace(0.0, math.pi / 2, 9)[1:]:
                        zs += [length / 2 + r * math.sin(a), -length / 2 - r * math.sin(a)]
                v = []
                for zz in zs:
                    rr = r if abs(zz) <= length / 2 + 1e-12 else math.sqrt(max(r * r - (abs(zz) - length / 2) ** 2, 0.0))
                    v.append(np.column_stack([rr * np.cos(ring), rr * np.sin(ring), np.full(len(ring), zz)]))
                v = np.vstack(v)
            elif geom == p.GEOM_SPHERE:
                r = float(dims[0])
                v = []
                for a in np.linspace(-math.pi / 2, math.pi / 2, 17):
                    v.append(np.column_stack([r * math.cos(a) * np.cos(ring), r * math.cos(a) * np.sin(ring), np.full(len(ring), r * math.sin(a))]))
                v = np.vstack(v)
            elif geom == p.GEOM_MESH and n_mesh > 0:
                v = np.asarray(mesh_v, dtype=np.float64)  # the convex hull's vertices, scaled, in the body frame
                out.append(v @ R_body.T + t_body)
                continue
            else:
                continue
            v = v @ R_loc.T + t_loc
            out.append(v @ R_body.T + t_body)
        return out

    @staticmethod
    def _slice(verts: NDArray[np.float64], z: float) -> NDArray[np.float64] | None:
        """``(K, 2)`` CCW cross-section at height ``z`` of the convex hull of ``verts`` (None if it misses)."""
        import shapely

        dz = verts[:, 2] - z
        above, below, on = verts[dz > 1e-12], verts[dz < -1e-12], verts[np.abs(dz) <= 1e-12]
        pts = [on[:, :2]]
        if len(above) and len(below):
            a = above[:, None, :]
            b = below[None, :, :]
            t = (a[..., 2] - z) / (a[..., 2] - b[..., 2])
            pts.append((a[..., :2] + t[..., None] * (b[..., :2] - a[..., :2])).reshape(-1, 2))
        pts = np.vstack(pts)
        if len(pts) < 3:
            return None
        hull = shapely.convex_hull(shapely.multipoints(pts))
        if hull.geom_type != "Polygon" or hull.area <= 0:
            return None
        ring = np.asarray(hull.exterior.coords)[:-1]
        if shapely.Polygon(ring).exterior.is_ccw is False:
            ring = ring[::-1]
        return ring

    def cast(self, origin: NDArray[np.float64], angles: NDArray[np.float64], range_max: float) -> NDArray[np.float64]:
        """Ranges ``(N,)`` (``inf``: nothing within ``range_max``) of rays from ``origin`` ``(2,)`` along the
        world-frame ``angles`` ``(N,)``, evenly spaced and increasing (a scan)."""
        n = len(angles)
        ranges = np.full(n, np.inf)
        if not len(self.segments) or n == 0:
            return ranges
        o = np.asarray(origin, dtype=np.float64)[:2]
        p0, e = self._p0, self._e
        # edges within range: distance from the origin to each edge
        w = o - p0
        ee = np.einsum("ij,ij->i", e, e)
        s = np.clip(np.einsum("ij,ij->i", w, e) / np.where(ee > 0, ee, 1.0), 0.0, 1.0)
        dist = np.hypot(*(p0 + s[:, None] * e - o).T)
        near = np.nonzero(dist < range_max)[0]
        if not len(near):
            return ranges
        p0, e = p0[near], e[near]
        a0 = np.arctan2(p0[:, 1] - o[1], p0[:, 0] - o[0])
        p1 = p0 + e
        a1 = np.arctan2(p1[:, 1] - o[1], p1[:, 0] - o[0])
        span = np.remainder(a1 - a0 + math.pi, 2 * math.pi) - math.pi
        lo = np.where(span >= 0, a0, a1)
        span = np.abs(span)
        inc = (angles[-1] - angles[0]) / (n - 1) if n > 1 else 2 * math.pi
        k0 = np.ceil(np.remainder(lo - angles[0], 2 * math.pi) / inc - 1e-9).astype(np.int64)
        k1 = np.floor((np.remainder(lo - angles[0], 2 * math.pi) + span) / inc + 1e-9).astype(np.int64)
        cnt = np.maximum(k1 - k0 + 1, 0)
        total = int(cnt.sum())
        if total == 0:
            return ranges
        seg = np.repeat(np.arange(len(near)), cnt)
        k = k0[seg] + (np.arange(total) - np.repeat(np.cumsum(cnt) - cnt, cnt))
        k %= n
        d = np.column_stack([np.cos(angles[k]), np.sin(angles[k])])
        q = p0[seg] - o
        es = e[seg]
        den = d[:, 0] * es[:, 1] - d[:, 1] * es[:, 0]
        ok = np.abs(den) > 1e-12
        den = np.where(ok, den, 1.0)
        t = (q[:, 0] * es[:, 1] - q[:, 1] * es[:, 0]) / den
        u = (q[:, 0] * d[:, 1] - q[:, 1] * d[:, 0]) / den
        hit = ok & (t > 0) & (u >= -1e-9) & (u <= 1 + 1e-9) & (t <= range_max)
        np.minimum.at(ranges, k[hit], t[hit])
        return ranges


def pose3(T: Pose2, z: float = 0.0) -> NDArray[np.float64]:
    """``(4, 4)`` homogeneous matrix of a planar pose at height ``z``."""
    c, s = math.cos(T.yaw), math.sin(T.yaw)
    M = np.eye(4)
    M[:2, :2] = [[c, -s], [s, c]]
    M[:3, 3] = (T.x, T.y, z)
    return M


def _quat_from_matrix(R: NDArray[np.float64]) -> tuple[float, float, float, float]:
    """(x, y, z, w) quaternion of a rotation matrix."""
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(R).as_quat()
    return (float(q[0]), float(q[1]), float(q[2]), float(q[3]))


class SimWorld:
    """A world, the robot and its sensors in a private pybullet client (see the module docstring)."""

    def __init__(self, world: World, config: Config, *, seed: int | None = None, renderer: str | None = None) -> None:
        """``renderer``: ``auto | egl | tiny`` (default ``config.sim.renderer``); the one in use is
        :attr:`renderer` (``"egl"`` or ``"tiny"``) with a human-readable :attr:`renderer_note`."""
        import pybullet as p

        self._p = p
        self.world = world
        self.config = config
        self.seed = int(config.sim.seed if seed is None else seed)
        self.dt = float(config.sim.physics_dt_s)
        self.robot_model = RobotModel.load()
        requested = renderer if renderer is not None else getattr(config.sim, "renderer", "auto")
        self.renderer, self.renderer_note = resolve_renderer(requested)
        self.client: int = p.connect(p.DIRECT)
        if self.client < 0:
            raise RuntimeError("pybullet: cannot open a DIRECT client")
        if self.renderer == "egl":  # before any body: the plugin only sees shapes created after it loads
            with quiet_c_stdout(stderr=True):
                plugin = p.loadPlugin(egl_plugin_path(), "_eglRendererPlugin", physicsClientId=self.client)
            if plugin < 0:
                if str(requested).lower() == "egl":
                    p.disconnect(self.client)
                    raise RendererError(f"pybullet could not load the EGL plugin. {EGL_INSTALL_HINT}")
                log.warning("EGL plugin did not load; using TinyRenderer")
                self.renderer, self.renderer_note = "tiny", "TinyRenderer (fallback: the EGL plugin did not load)"
        self._renderer_flag = p.ER_BULLET_HARDWARE_OPENGL if self.renderer == "egl" else p.ER_TINY_RENDERER
        #: the EGL plugin's OpenGL context is current on the thread that loaded it only: a render from any
        #: other thread crashes the process (even with ER_TINY_RENDERER), so it is refused instead
        self._gl_thread: int | None = threading.get_ident() if self.renderer == "egl" else None
        self.object_body_ids: dict[int, list[int]] = {}
        #: body id → (kind, index, role): kind "object" | "obstacle" | "wall" | "floor" | "glass"
        self.body_info: dict[int, tuple[str, int, str]] = {}
        self._world_bodies: set[int] = set()
        try:
            self._build()
        except Exception:
            p.disconnect(self.client)
            raise
        self.reset()

    # ------------------------------------------------------------------------------------------
    # construction
    # ------------------------------------------------------------------------------------------
    def _build(self) -> None:
        p, cid, w = self._p, self.client, self.world
        mf = egl_mesh_alias if self.renderer == "egl" else None
        xmin, ymin, xmax, ymax = w.bounds()
        cx, cy = (xmin + xmax) / 2, (ymin + ymax) / 2
        hx, hy = (xmax - xmin) / 2 + 1.0, (ymax - ymin) / 2 + 1.0
        floor = p.createMultiBody(
            0.0,
            p.createCollisionShape(p.GEOM_BOX, halfExtents=[hx, hy, 0.005], physicsClientId=cid),
            p.createVisualShape(p.GEOM_BOX, halfExtents=[hx, hy, 0.005], rgbaColor=[*w.floor_color, 1.0], physicsClientId=cid),
            [cx, cy, -0.005],
            physicsClientId=cid,
        )
        self.floor_body = floor
        self.body_info[floor] = ("floor", 0, "floor")
        p.setCollisionFilterGroupMask(floor, -1, _G_FLOOR, 0, physicsClientId=cid)
        self.wall_body_ids: list[list[int]] = []
        for i, wall in enumerate(w.walls):
            ids = []
            color = wall.color or w.wall_color
            for s0, s1, z0, z1, th, yaw in wall.boxes():
                mx, my = wall.point_at((s0 + s1) / 2)
                he = [(s1 - s0) / 2, th / 2, (z1 - z0) / 2]
                b = self._static_box(he, (mx, my, (z0 + z1) / 2), yaw, color)
                self.body_info[b] = ("wall", i, "wall")
                ids.append(b)
            for o in wall.openings:
                if o.kind != "window":
                    continue
                mx, my = wall.point_at((o.start + o.end) / 2)
                he = [(o.end - o.start) / 2, 0.01, (o.top - o.bottom) / 2]
                b = self._static_box(he, (mx, my, (o.bottom + o.top) / 2), wall.yaw, _GLASS)
                self.body_info[b] = ("glass", i, "glass")
                ids.append(b)
            self.wall_body_ids.append(ids)
        self.obstacle_body_ids: list[list[int]] = []
        for i, o in enumerate(w.obstacles):
            ids = []
            if o.shape == "box":
                ids.append(self._static_box([v / 2 for v in o.size], (o.x, o.y, o.z + o.size[2] / 2), o.yaw, o.color or (0.6, 0.6, 0.6)))
            elif o.shape == "cylinder":
                col = p.createCollisionShape(p.GEOM_CYLINDER, radius=o.radius, height=o.height, physicsClientId=cid)
                vis = p.createVisualShape(
                    p.GEOM_CYLINDER, radius=o.radius, length=o.height, rgbaColor=[*(o.color or (0.6, 0.6, 0.6)), 1.0], physicsClientId=cid
                )
                ids.append(p.createMultiBody(0.0, col, vis, [o.x, o.y, o.z + o.height / 2], physicsClientId=cid))
            else:
                spec = get_model(o.model)
                built = build_model_pybullet(cid, o.model, o.x, o.y, o.yaw, z=o.z, scale=o.scale, colors=resolve_colors(spec, o.color), mesh_file=mf)
                ids.extend(b for b, _ in built)
                for b, role in built:
                    self.body_info[b] = ("obstacle", i, role)
            for b in ids:
                self.body_info.setdefault(b, ("obstacle", i, "body"))
            self.obstacle_body_ids.append(ids)
        for i, o in enumerate(w.objects):
            spec = get_model(o.model)
            built = build_model_pybullet(cid, o.model, o.x, o.y, o.yaw, scale=o.scale, colors=resolve_colors(spec, o.color), mesh_file=mf)
            self.object_body_ids[i] = [b for b, _ in built]
            for b, role in built:
                self.body_info[b] = ("object", i, role)
        for b, (kind, _, _) in self.body_info.items():
            if kind != "floor":
                p.setCollisionFilterGroupMask(b, -1, _G_WORLD, _G_WORLD, physicsClientId=cid)
                self._world_bodies.add(b)
        # segmentation lookup: body id → ground-truth object id (-1 otherwise)
        n = max(self.body_info) + 64
        self._seg_lut = np.full(n + 1, -1, dtype=np.int32)
        for b, (kind, i, _) in self.body_info.items():
            if kind == "object":
                self._seg_lut[b] = i
        # the robot (kinematic, visual only) and its collision probe
        rm = self.robot_model
        self.robot_body = p.loadURDF(
            str(rm.urdf_path),
            [0, 0, 0],
            useFixedBase=True,
            flags=p.URDF_USE_IMPLICIT_CYLINDER,
            physicsClientId=cid,
        )
        self._robot_inertial_offset = np.asarray(p.getDynamicsInfo(self.robot_body, -1, physicsClientId=cid)[3])
        self._wheel_joint_index: dict[str, int] = {}
        for j in range(p.getNumJoints(self.robot_body, physicsClientId=cid)):
            info = p.getJointInfo(self.robot_body, j, physicsClientId=cid)
            self._wheel_joint_index[info[1].decode()] = j
            p.setCollisionFilterGroupMask(self.robot_body, j, _G_ROBOT, 0, physicsClientId=cid)
        p.setCollisionFilterGroupMask(self.robot_body, -1, _G_ROBOT, 0, physicsClientId=cid)
        self.robot_radius = float(self.config.robot.footprint_radius_m)
        h = float(self.config.sim.robot_height_m)
        self._probe_z = (0.012 + h) / 2  # from 12 mm above the floor (rugs, cables) to the robot's top
        probe_col = p.createCollisionShape(p.GEOM_CYLINDER, radius=self.robot_radius, height=h - 0.012, physicsClientId=cid)
        self._probe = p.createMultiBody(0.0, probe_col, -1, list(_FAR_AWAY), physicsClientId=cid)
        p.setCollisionFilterGroupMask(self._probe, -1, _G_CHECK, 0, physicsClientId=cid)
        self._robot_synced = False
        self._planar: PlanarCaster | None = None  # the LIDAR plane's outlines, built at the first scan

    def _static_box(self, he: Sequence[float], pos: Sequence[float], yaw: float, color: Sequence[float]) -> int:
        p, cid = self._p, self.client
        col = p.createCollisionShape(p.GEOM_BOX, halfExtents=list(he), physicsClientId=cid)
        vis = p.createVisualShape(p.GEOM_BOX, halfExtents=list(he), rgbaColor=[*color[:3], 1.0], physicsClientId=cid)
        q = p.getQuaternionFromEuler([0.0, 0.0, yaw])
        return p.createMultiBody(0.0, col, vis, list(pos), q, physicsClientId=cid)

    # ------------------------------------------------------------------------------------------
    # state
    # ------------------------------------------------------------------------------------------
    def reset(self) -> None:
        """Back to the world's start pose at t = 0, wheels at zero, noise re-seeded.

        Each noise source has its own stream (motion/slip, encoders, LIDAR, camera) spawned from the
        seed, so which sensors are read, and how often, never changes the robot's true trajectory."""
        ss = np.random.SeedSequence(self.seed)
        self.rng_motion, self.rng_encoders, self.rng_lidar, self.rng_camera = (np.random.default_rng(s) for s in ss.spawn(4))
        self.time = 0.0
        self._steps = 0
        self._pose = np.array([self.world.start.x, self.world.start.y, self.world.start.yaw], dtype=np.float64)
        self._phi = np.zeros(2)  # true wheel angles (left, right)
        self._omega = np.zeros(2)  # actual wheel rates
        self._omega_cmd = np.zeros(2)
        self._slip = np.zeros(2)
        e = self.config.encoders
        self._radius_scale = 1.0 + self.rng_motion.normal(0.0, e.radius_error_std, 2) if e.radius_error_std > 0 else np.ones(2)
        self._blocked = False
        self.collisions = 0
        self.distance_m = 0.0
        self._robot_synced = False
        self._noise_banks: dict[tuple, NDArray[np.int16]] = {}

    @property
    def wheel_angles(self) -> tuple[float, float]:
        """True (left, right) wheel angles in rad (ground truth; the encoders add noise)."""
        return float(self._phi[0]), float(self._phi[1])

    def true_pose(self) -> Pose2:
        """Ground truth ``T_world_base`` (``base_footprint`` in the world frame)."""
        return Pose2(float(self._pose[0]), float(self._pose[1]), float(wrap_angle(self._pose[2])))

    def set_time(self, t: float) -> None:
        """Set the sim clock (restoring a session), rounded to whole physics steps."""
        self._steps = max(0, int(round(float(t) / self.dt)))
        self.time = self._steps * self.dt

    def set_robot_pose(self, T_world_base: Pose2) -> None:
        """Teleport the robot (no collision check; motion state kept, stall cleared)."""
        self._pose = np.array([T_world_base.x, T_world_base.y, T_world_base.yaw], dtype=np.float64)
        self._blocked = False
        self._robot_synced = False

    def set_cmd_vel(self, twist: Twist) -> None:
        """cmd_vel: wheel-rate targets from :func:`twist_to_wheel_rates` (clamped to the robot's limits)."""
        wl, wr = twist_to_wheel_rates(twist, self.config.robot)
        self._omega_cmd = np.array([wl, wr], dtype=np.float64)

    def in_collision(self) -> bool:
        """True while the robot is stalled against an obstacle (its last step was refused)."""
        return self._blocked

    def pose_free(self, x: float, y: float) -> bool:
        """True if the robot's collision cylinder at ``(x, y)`` touches nothing."""
        p, cid = self._p, self.client
        r = self.robot_radius
        z = self._probe_z
        hh = self.config.sim.robot_height_m / 2
        cands = p.getOverlappingObjects([x - r, y - r, z - hh], [x + r, y + r, z + hh], physicsClientId=cid)
        if not cands:
            return True
        moved = False
        for uid, _ in cands:
            if uid not in self._world_bodies:
                continue
            if not moved:
                p.resetBasePositionAndOrientation(self._probe, [x, y, z], [0, 0, 0, 1], physicsClientId=cid)
                moved = True
            if p.getClosestPoints(self._probe, uid, 0.0, physicsClientId=cid):
                return False
        return True

    def step(self, n: int = 1) -> None:
        """Advance ``n`` fixed steps of ``dt``."""
        dt = self.dt
        e = self.config.encoders
        tau = self.config.sim.motor_time_constant_s
        k_motor = 1.0 - math.exp(-dt / tau) if tau > 0 else 1.0
        a_slip = math.exp(-dt / max(e.slip_tau_s, 1e-9))
        b_slip = e.slip_std * math.sqrt(max(1.0 - a_slip * a_slip, 0.0))
        r = self.robot_model.wheel_radius_m
        sep = self.robot_model.wheel_separation_m
        rng = self.rng_motion
        for _ in range(int(n)):
            self._omega += (self._omega_cmd - self._omega) * k_motor
            if b_slip > 0:
                self._slip = self._slip * a_slip + b_slip * rng.standard_normal(2)
            self._phi += self._omega * dt
            ground = r * self._radius_scale * self._omega * (1.0 - self._slip)
            v = 0.5 * (ground[0] + ground[1])
            w = (ground[1] - ground[0]) / sep
            x, y, th = self._pose
            if abs(v) > 1e-12 or abs(w) > 1e-12:
                if abs(w) < 1e-9:
                    nx, ny = x + v * dt * math.cos(th), y + v * dt * math.sin(th)
                else:
                    R = v / w
                    nx = x + R * (math.sin(th + w * dt) - math.sin(th))
                    ny = y - R * (math.cos(th + w * dt) - math.cos(th))
                nth = th + w * dt
                if (nx != x or ny != y) and not self.pose_free(nx, ny):
                    # stall: the cylinder may still turn in place; the wheels slip
                    if not self._blocked:
                        self.collisions += 1
                    self._blocked = True
                    self._pose = np.array([x, y, nth])
                else:
                    self._blocked = False
                    self.distance_m += math.hypot(nx - x, ny - y)
                    self._pose = np.array([nx, ny, nth])
                self._robot_synced = False
            self._steps += 1
            self.time = self._steps * dt

    # ------------------------------------------------------------------------------------------
    # sensors
    # ------------------------------------------------------------------------------------------
    def read_encoders(self) -> WheelEncoders:
        """Absolute wheel angles with Gaussian reading noise and quantisation, stamped with sim time."""
        e = self.config.encoders
        phi = self._phi.copy()
        if e.noise_std_rad > 0:
            phi = phi + self.rng_encoders.normal(0.0, e.noise_std_rad, 2)
        if e.resolution_rad > 0:
            phi = np.round(phi / e.resolution_rad) * e.resolution_rad
        return WheelEncoders(stamp=self.time, left_rad=float(phi[0]), right_rad=float(phi[1]))

    def T_world_base3(self) -> NDArray[np.float64]:
        """``(4, 4)`` ground-truth pose of base_footprint (on the floor)."""
        return pose3(self.true_pose())

    def scan(self) -> LaserScan:
        """One LIDAR sweep from ``base_scan``: ``beams`` rays over 360° from -π, Gaussian range noise,
        ``inf`` for no return within ``range_max``, ``-inf`` for a return closer than ``range_min``."""
        p, cid = self._p, self.client
        c = self.config.lidar
        n = int(c.beams)
        T = self.T_world_base3() @ self.robot_model.T_base_scan
        inc = 2.0 * math.pi / n
        ang = -math.pi + inc * np.arange(n)
        origin = T[:3, 3]
        if getattr(c, "caster", "planar") == "planar" and abs(T[2, 2] - 1.0) < 1e-9:
            if self._planar is None or abs(self._planar.z - origin[2]) > 1e-9:
                self._planar = PlanarCaster(p, cid, self._world_bodies, float(origin[2]))
            ranges = self._planar.cast(origin[:2], ang + math.atan2(T[1, 0], T[0, 0]), float(c.range_max_m))
        else:
            d_local = np.stack([np.cos(ang), np.sin(ang), np.zeros(n)], axis=1)
            d_world = d_local @ T[:3, :3].T
            to = origin + d_world * c.range_max_m
            frm = np.broadcast_to(origin, to.shape)
            res = p.rayTestBatch(frm.tolist(), to.tolist(), collisionFilterMask=_G_WORLD, physicsClientId=cid)
            frac = np.fromiter((h[2] if h[0] >= 0 else np.inf for h in res), dtype=np.float64, count=n)
            ranges = frac * c.range_max_m
        hit = np.isfinite(ranges)
        if c.noise_std_m > 0:
            ranges[hit] += self.rng_lidar.normal(0.0, c.noise_std_m, int(hit.sum()))
        with np.errstate(invalid="ignore"):
            ranges[hit & (ranges > c.range_max_m)] = np.inf
            ranges[hit & (ranges < c.range_min_m)] = -np.inf
        return LaserScan(
            stamp=self.time,
            angle_min=-math.pi,
            angle_increment=inc,
            range_min=float(c.range_min_m),
            range_max=float(c.range_max_m),
            ranges=ranges,
            frame_id="base_scan",
        )

    def camera_size(self) -> tuple[int, int]:
        """The default render size: ``camera.render_width`` (aspect kept) or the full ``width × height``."""
        c = self.config.camera
        if c.render_width and c.render_width < c.width:
            w = int(c.render_width)
            return w, max(1, int(round(c.height * w / c.width)))
        return int(c.width), int(c.height)

    def camera_info(self, width: int | None = None, height: int | None = None) -> CameraInfo:
        """Ideal pinhole intrinsics at a render size (K from the horizontal FOV)."""
        if width is None or height is None:
            width, height = self.camera_size()
        return CameraInfo.from_fov(int(width), int(height), self.config.camera.hfov_rad)

    def _sync_robot(self) -> None:
        if self._robot_synced:
            return
        p, cid = self._p, self.client
        M = self.T_world_base3()
        pos = M[:3, :3] @ self._robot_inertial_offset + M[:3, 3]
        q = p.getQuaternionFromEuler([0.0, 0.0, float(self._pose[2])])
        p.resetBasePositionAndOrientation(self.robot_body, pos.tolist(), q, physicsClientId=cid)
        for name, phi in zip(self.robot_model.wheel_joint_names, self._phi):
            j = self._wheel_joint_index.get(name)
            if j is not None:
                p.resetJointState(self.robot_body, j, float(phi), physicsClientId=cid)
        self._robot_synced = True

    def render_camera(
        self, width: int | None = None, height: int | None = None, *, depth: bool = False, segmentation: bool = False
    ) -> CameraFrame:
        """The robot's camera (``camera_optical_frame``), with pixel noise ``camera.noise_std``."""
        if width is None or height is None:
            width, height = self.camera_size()
        self._sync_robot()
        T = self.T_world_base3() @ self.robot_model.T_base_camera_optical
        frame = self._render(T, int(width), int(height), depth=depth, segmentation=segmentation)
        sigma = float(self.config.camera.noise_std)
        if sigma > 0:
            frame.image = Image(stamp=frame.stamp, data=self._add_pixel_noise(frame.image.data, sigma))
        return frame

    def _add_pixel_noise(self, rgb: NDArray[np.uint8], sigma: float) -> NDArray[np.uint8]:
        """Gaussian pixel noise σ (0–255), cheaply: a random window of a per-size noise bank
        (drawing ~10⁶ normals per 640×480 frame would cost more than half a render)."""
        h, w, _ = rgb.shape
        key = (h, w, sigma)
        bank = self._noise_banks.get(key)
        if bank is None:
            bank = np.round(self.rng_camera.normal(0.0, sigma, (h + 61, w + 67, 3))).astype(np.int16)
            self._noise_banks = {key: bank}
        dy = int(self.rng_camera.integers(0, bank.shape[0] - h + 1))
        dx = int(self.rng_camera.integers(0, bank.shape[1] - w + 1))
        out = rgb.astype(np.int16)
        out += bank[dy : dy + h, dx : dx + w]
        return np.clip(out, 0, 255).astype(np.uint8)

    def render_view(
        self,
        T_world_base: Pose2,
        *,
        width: int,
        height: int,
        camera_z: float | None = None,
        pitch_rad: float = 0.0,
        light: dict | None = None,
        segmentation: bool = True,
        depth: bool = False,
        hide_robot: bool = True,
    ) -> CameraFrame:
        """Render from the camera of a robot standing at ``T_world_base`` (for datasets).

        ``camera_z`` replaces the optical centre's height; ``pitch_rad > 0`` tilts the camera down.
        ``light``: pybullet ``getCameraImage`` light arguments (``lightDirection``, ``lightColor``,
        ``lightAmbientCoeff``, ``lightDiffuseCoeff``, ``lightSpecularCoeff``, ``shadow``). The simulated
        robot is moved out of view unless ``hide_robot`` is False. No pixel noise is added.
        """
        T = pose3(T_world_base) @ self.robot_model.T_base_camera_optical
        if camera_z is not None:
            T[2, 3] = float(camera_z)
        if pitch_rad:
            c, s = math.cos(-pitch_rad), math.sin(-pitch_rad)
            Rx = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
            T[:3, :3] = T[:3, :3] @ Rx
        p, cid = self._p, self.client
        if hide_robot:
            p.resetBasePositionAndOrientation(self.robot_body, list(_FAR_AWAY), [0, 0, 0, 1], physicsClientId=cid)
            self._robot_synced = False
        else:
            self._sync_robot()
        return self._render(T, int(width), int(height), depth=depth, segmentation=segmentation, light=light)

    def _render(
        self,
        T_world_cam: NDArray[np.float64],
        width: int,
        height: int,
        *,
        depth: bool,
        segmentation: bool,
        light: dict | None = None,
    ) -> CameraFrame:
        p, cid = self._p, self.client
        if self._gl_thread is not None and threading.get_ident() != self._gl_thread:
            raise RendererError(
                "the EGL renderer draws only on the thread that built this world; "
                "build it on the rendering thread or use sim.renderer=tiny"
            )
        cc = self.config.camera
        info = CameraInfo.from_fov(width, height, cc.hfov_rad)
        eye = T_world_cam[:3, 3]
        z_axis, y_axis = T_world_cam[:3, 2], T_world_cam[:3, 1]
        view = p.computeViewMatrix(eye.tolist(), (eye + z_axis).tolist(), (-y_axis).tolist(), physicsClientId=cid)
        fov_y = math.degrees(2.0 * math.atan((height / 2.0) / info.K[1, 1]))
        near, far = float(cc.near_m), float(cc.far_m)
        proj = p.computeProjectionMatrixFOV(fov_y, width / height, near, far, physicsClientId=cid)
        try:
            light_dir = [float(v) for v in self.config.sim.light_direction]
            if len(light_dir) != 3 or not all(math.isfinite(v) for v in light_dir):
                raise ValueError
        except (TypeError, ValueError):
            light_dir = [0.3, -0.4, 1.0]  # a malformed sim.light_direction must not stop the camera
        kw: dict[str, Any] = dict(
            lightDirection=light_dir,
            lightAmbientCoeff=float(self.config.sim.light_ambient),
            lightDiffuseCoeff=float(self.config.sim.light_diffuse),
            shadow=0,
        )
        if light:
            kw.update(light)
        flags = 0 if segmentation else p.ER_NO_SEGMENTATION_MASK
        with quiet_c_stdout() if self.renderer == "egl" else contextlib.nullcontext():
            _, _, rgba, zbuf, seg = p.getCameraImage(
                width, height, view, proj, renderer=self._renderer_flag, flags=flags, physicsClientId=cid, **kw
            )
        rgb = np.ascontiguousarray(np.reshape(np.asarray(rgba, dtype=np.uint8), (height, width, 4))[:, :, :3])
        frame = CameraFrame(stamp=self.time, image=Image(stamp=self.time, data=rgb), info=info, T_world_camera=T_world_cam)
        if depth:
            d = np.reshape(np.asarray(zbuf, dtype=np.float64), (height, width))
            frame.depth = (far * near / (far - (far - near) * d)).astype(np.float32)
        if segmentation:
            s = np.reshape(np.asarray(seg, dtype=np.int64), (height, width))
            out = np.full(s.shape, -1, dtype=np.int32)
            ok = (s >= 0) & (s < len(self._seg_lut))
            out[ok] = self._seg_lut[s[ok]]
            frame.segmentation = out
        return frame

    # ------------------------------------------------------------------------------------------
    # ground truth
    # ------------------------------------------------------------------------------------------
    def ground_truth_objects(self) -> list[GroundTruthObject]:
        """Every classified object: id (= index in ``world.objects``, as in segmentations), class,
        pose, CCW footprint polygon and height range, in the world frame."""
        out = []
        for i, o in enumerate(self.world.objects):
            z0, z1 = o.z_range()
            out.append(
                GroundTruthObject(
                    id=i,
                    label=o.label,
                    pose=o.pose,
                    footprint=o.footprint(),
                    z_min=z0,
                    z_max=z1,
                    legged=o.legged,
                    name=self.world.object_name(i),
                    frame_id="world",
                )
            )
        return out

    def ground_truth_obstacles(self) -> list[GroundTruthObstacle]:
        """Walls (one entry per solid piece, openings cut out) and unclassified obstacles, world frame."""
        out = []
        for i, w in enumerate(self.world.walls):
            for k, (s0, s1, z0, z1, _, _) in enumerate(w.boxes()):
                poly = np.asarray(w._span_polygon(s0, s1).exterior.coords)[:-1]
                out.append(GroundTruthObstacle(poly, z0, z1, kind="wall", name=f"walls[{i}]" + (f" {w.name}" if w.name else "")))
        for i, o in enumerate(self.world.obstacles):
            z0, z1 = o.z_range()
            out.append(GroundTruthObstacle(o.footprint(), z0, z1, kind="obstacle", name=o.name or f"obstacles[{i}]"))
        return out

    # ------------------------------------------------------------------------------------------
    # domain randomisation helpers
    # ------------------------------------------------------------------------------------------
    def set_body_color(self, body: int, rgb: Sequence[float]) -> None:
        self._p.changeVisualShape(body, -1, rgbaColor=[*map(float, rgb[:3]), 1.0], physicsClientId=self.client)

    def set_object_color(self, object_id: int, rgb: Sequence[float], role: str | None = None) -> None:
        """Recolour an object's parts of ``role`` (default: the model's primary role)."""
        spec = get_model(self.world.objects[object_id].model)
        role = role or spec.primary
        for b in self.object_body_ids[object_id]:
            if self.body_info[b][2] == role:
                self.set_body_color(b, rgb)

    def set_floor_color(self, rgb: Sequence[float]) -> None:
        self.set_body_color(self.floor_body, rgb)

    def set_wall_color(self, rgb: Sequence[float]) -> None:
        for ids in self.wall_body_ids:
            for b in ids:
                if self.body_info[b][0] == "wall":
                    self.set_body_color(b, rgb)

    def close(self) -> None:
        """Disconnect the pybullet client (idempotent)."""
        if getattr(self, "client", -1) >= 0:
            try:
                with quiet_c_stdout() if getattr(self, "renderer", "tiny") == "egl" else contextlib.nullcontext():
                    self._p.disconnect(self.client)
            except Exception:
                pass
            self.client = -1

    def __enter__(self) -> "SimWorld":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:  # pragma: no cover - best effort
        try:
            self.close()
        except Exception:
            pass
