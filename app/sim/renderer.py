"""The camera renderer's choice and the EGL plugin's plumbing.

``sim.renderer`` (``auto | egl | tiny``): pybullet's EGL renderer plugin (OpenGL; Mesa's llvmpipe without a
GPU) where it loads, else TinyRenderer. The EGL plugin is first probed in a child process (a broken EGL
stack exits the process that loads it), once per process tree: the verdict reaches child processes (the
render worker, the dataset pool) through ``$OCSLAM_EGL_PROBE``. The plugin prints to C's stdout at load
and at every render (:func:`quiet_c_stdout` silences it) and caches meshes by file name
(:func:`egl_mesh_alias` gives each scale of a mesh its own name).
"""

from __future__ import annotations

import contextlib
import ctypes
import importlib.util
import json
import logging
import os
import subprocess
import sys
import threading
from collections.abc import Iterator, Sequence
from typing import Any

__all__ = [
    "EGL_INSTALL_HINT", "EGL_PLUGIN_ENV", "EGL_PROBE_ENV", "RENDERERS", "RENDERER_ENV", "RenderClient", "RendererError",
    "egl_mesh_alias", "egl_plugin_path", "load_egl_plugin", "probe_egl", "quiet_c_stdout", "resolve_renderer",
]

log = logging.getLogger(__name__)

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



def load_egl_plugin(p: Any, client: int) -> int:
    """Load the EGL plugin into a pybullet client; its id, negative if it did not load. Load it before any
    body: the plugin only sees shapes created after it loads."""
    with quiet_c_stdout(stderr=True):
        return p.loadPlugin(egl_plugin_path(), "_eglRendererPlugin", physicsClientId=client)


class RenderClient:
    """A pybullet DIRECT client with its renderer chosen (:func:`resolve_renderer`) and, for EGL, the
    plugin loaded, lent to one world after another.

    :class:`~app.sim_world.SimWorld` opens its own unless it is given one. A process that builds many
    worlds (a dataset worker) keeps one: :meth:`lend` empties the simulation instead of a new client
    loading the plugin again (0.2–0.3 s a world on llvmpipe); the images are the same.

    Attributes: ``id`` (the pybullet client id), ``renderer`` (``"egl"`` or ``"tiny"``), ``note`` (how it
    was chosen), ``gl_thread`` (the thread whose OpenGL context the plugin uses; ``None`` for TinyRenderer).
    """

    def __init__(self, requested: str = "auto") -> None:
        import pybullet as p

        self._p = p
        self.renderer, self.note = resolve_renderer(requested)
        self.id: int = p.connect(p.DIRECT)
        if self.id < 0:
            raise RuntimeError("pybullet: cannot open a DIRECT client")
        if self.renderer == "egl" and load_egl_plugin(p, self.id) < 0:
            if str(requested).lower() == "egl":
                self.close()
                raise RendererError(f"pybullet could not load the EGL plugin. {EGL_INSTALL_HINT}")
            log.warning("EGL plugin did not load; using TinyRenderer")
            self.renderer, self.note = "tiny", "TinyRenderer (fallback: the EGL plugin did not load)"
        #: the EGL plugin's OpenGL context is current on the thread that loaded it only
        self.gl_thread: int | None = threading.get_ident() if self.renderer == "egl" else None
        self._used = False  # a world was built in it: the next lend empties it first

    def lend(self) -> int:
        """The client id, emptied (``resetSimulation``) if a world was built in it before."""
        if self.id < 0:
            raise RuntimeError("the render client is closed")
        if self._used:
            self._p.resetSimulation(physicsClientId=self.id)
        self._used = True
        return self.id

    def close(self) -> None:
        """Disconnect (idempotent); the EGL plugin is unloaded with the client."""
        if self.id >= 0:
            try:
                with quiet_c_stdout() if self.renderer == "egl" else contextlib.nullcontext():
                    self._p.disconnect(self.id)
            except Exception:
                pass
            self.id = -1
