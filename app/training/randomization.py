"""Domain randomisation of the dataset renders (``ocslam dataset``, see :mod:`app.training.dataset`).

Per world, re-drawn every ``rerandomize_every`` images by :class:`Randomizer`: light direction, colour
and intensity (ambient/diffuse/specular, sometimes shadows); floor and wall colours and procedural
textures (:func:`make_texture`: planks, tiles, checker, carpet noise, stripes, marble, plain) on overlay
meshes; object colour jitter; distractor objects of no class (``pybullet_data/random_urdfs``, scaled and
recoloured). Per image, :func:`sensor_effects`: gamma/contrast/colour balance, blur, motion blur,
Gaussian noise. Every draw comes from the caller's ``np.random.Generator``, so a seeded dataset is
reproducible.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from app.world.models.bodies import body_flags

__all__ = ["TEXTURE_KINDS", "Randomizer", "make_texture", "sensor_effects", "urdf_mesh_box"]


def _hsv(h: float, s: float, v: float) -> tuple[float, float, float]:
    import colorsys

    return colorsys.hsv_to_rgb(h % 1.0, min(max(s, 0), 1), min(max(v, 0), 1))


def make_texture(kind: str, rng: np.random.Generator, size: int = 128) -> np.ndarray:
    """A procedural ``(size, size, 3)`` uint8 RGB texture that tiles: planks, tiles, checker, carpet,
    stripes, marble or plain."""
    base = np.array(_hsv(rng.random(), rng.uniform(0.05, 0.6), rng.uniform(0.3, 0.95)))
    alt = np.array(_hsv(rng.random(), rng.uniform(0.0, 0.6), rng.uniform(0.2, 0.95)))
    yy, xx = np.mgrid[0:size, 0:size] / size
    grain = rng.normal(0.0, 1.0, (size, size))
    if kind == "planks":
        n = int(rng.integers(3, 9))
        band = np.floor(yy * n).astype(int)
        tint = rng.uniform(0.8, 1.15, n)[band]
        line = (np.abs((yy * n) % 1.0) < 0.04) * 0.35
        g = cv2.GaussianBlur(grain, (0, 0), sigmaX=6, sigmaY=0.7) * 0.25
        img = base[None, None] * (tint * (1 + g) * (1 - line))[..., None]
    elif kind == "tiles":
        n = int(rng.integers(2, 6))
        grout = ((xx * n) % 1.0 < 0.05) | ((yy * n) % 1.0 < 0.05)
        img = np.where(grout[..., None], alt[None, None] * 0.6, base[None, None] * (1 + 0.05 * grain[..., None]))
    elif kind == "checker":
        n = int(rng.integers(2, 5)) * 2
        c = ((np.floor(xx * n) + np.floor(yy * n)) % 2).astype(bool)
        img = np.where(c[..., None], base[None, None], alt[None, None])
    elif kind == "carpet":
        g = cv2.GaussianBlur(grain, (0, 0), 1.2)
        img = base[None, None] * (1 + 0.35 * g[..., None] / max(g.std(), 1e-6) * 0.3)
    elif kind == "stripes":
        n = int(rng.integers(4, 16))
        c = (np.floor(xx * n) % 2).astype(bool)
        img = np.where(c[..., None], base[None, None], base[None, None] * 0.5 + alt[None, None] * 0.5)
    elif kind == "marble":
        g = cv2.GaussianBlur(grain, (0, 0), 10)
        g = g / max(np.abs(g).max(), 1e-6)
        v = 0.5 + 0.5 * np.sin((xx + yy) * 12 + 6 * g)
        img = base[None, None] * (1 - 0.3 * v[..., None]) + alt[None, None] * 0.3 * v[..., None]
    else:  # plain
        img = np.broadcast_to(base[None, None], (size, size, 3)) * (1 + 0.03 * grain[..., None])
    return np.clip(img * 255.0, 0, 255).astype(np.uint8)


#: ``cv2.imwrite`` flags of a PNG stored without compression (no row filters, zlib level 0): 0.4 ms for a
#: 320×240 render against 2 ms compressed, the same pixels (read by every PNG decoder)
PNG_STORED = (cv2.IMWRITE_PNG_COMPRESSION, 0, cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_NONE)

TEXTURE_KINDS = ("planks", "tiles", "checker", "carpet", "stripes", "marble", "plain")


def quad_obj_geometry(quads: list[tuple[np.ndarray, np.ndarray, np.ndarray, float]]) -> str:
    """The vertex, UV, normal and face lines of planar quads ``(origin, u_vec, v_vec, tile)`` as Wavefront OBJ
    text (corners ``o``, ``o+u``, ``o+u+v``, ``o+v``; the texture repeats every ``tile`` metres)."""
    lines = []
    faces = []
    for q, (o, u, v, tile) in enumerate(quads):
        n = np.cross(u, v)
        n = n / (np.linalg.norm(n) or 1.0)
        lu, lv = np.linalg.norm(u) / tile, np.linalg.norm(v) / tile
        for c, uv in ((o, (0.0, 0.0)), (o + u, (lu, 0.0)), (o + u + v, (lu, lv)), (o + v, (0.0, lv))):
            lines.append("v {:.6f} {:.6f} {:.6f}".format(*c))
            lines.append(f"vt {uv[0]:.6f} {uv[1]:.6f}")
            lines.append("vn {:.6f} {:.6f} {:.6f}".format(*n))
        k = 4 * q + 1  # OBJ indices are 1-based; vertex k has uv k and normal k
        faces += [(k, k + 1, k + 2), (k, k + 2, k + 3)]
    lines += [f"f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}" for a, b, c in faces]
    return "\n".join(lines) + "\n" if lines else ""


def write_mesh_obj(geometry: str, path: Path, material: str | None = None) -> Path:
    """Write OBJ ``geometry`` text (:func:`quad_obj_geometry`) as a Wavefront OBJ mesh file, using the first
    material of the ``material`` file (beside it) if given; returns ``path``.

    A mesh *file*, not pybullet's vertex arrays: the EGL renderer plugin draws only meshes it can load
    by file name (vertex-array meshes are skipped with "issue extracting mesh"), TinyRenderer draws both."""
    head = ["# OCSLAM dataset overlay (app/training/randomization.py)"]
    if material:
        head += [f"mtllib {material}", "usemtl m"]
    path = Path(path)
    path.write_text("\n".join(head) + "\n" + geometry)
    return path


@functools.lru_cache(maxsize=4)
def _distractor_urdfs(data_path: str) -> tuple[Path, ...]:
    """pybullet_data's ``random_urdfs`` (listed once a process: a directory walk of 1,000 files)."""
    return tuple(sorted((Path(data_path) / "random_urdfs").glob("*/*.urdf")))


@functools.cache
def urdf_mesh_box(path: str) -> np.ndarray | None:
    """``[[xmin, ymin], [xmax, ymax]]``: the planar bounds of a one-link URDF's collision mesh in its link
    frame at ``globalScaling`` 1 (the mesh's vertices times its ``scale``), or ``None`` for any other URDF
    (joints, several collision shapes, an offset origin, no mesh, a vertex that is not a finite number, an
    unreadable file).

    pybullet bounds a convex mesh by its local box turned into the world (plus a small collision margin),
    so a body loaded at ``(x, y)``, turned by ``yaw`` and scaled by ``s`` has the planar AABB centre
    ``(x, y) + R(yaw)·s·c`` (``c`` the box's centre) exactly and half extents at least ``|R(yaw)|·s·h``:
    :meth:`Randomizer._place_distractors` turns down a draw that surely does not fit before loading it."""
    import re
    import xml.etree.ElementTree as ET

    try:
        root = ET.parse(path).getroot()
        links = root.findall("link")
        if len(links) != 1 or root.findall("joint"):
            return None
        cols = links[0].findall("collision")
        if len(cols) != 1:
            return None
        origin = cols[0].find("origin")
        if origin is not None and any(float(v) != 0.0 for k in ("xyz", "rpy") for v in origin.get(k, "0 0 0").split()):
            return None
        mesh = cols[0].find("geometry/mesh")
        if mesh is None or not mesh.get("filename"):
            return None
        scale = np.array([float(v) for v in mesh.get("scale", "1 1 1").split()], dtype=np.float64)
        data = (Path(path).parent / str(mesh.get("filename"))).read_bytes()
        v = np.array(re.findall(rb"^v\s+(\S+)\s+(\S+)\s", data, re.M), dtype=np.float64).reshape(-1, 2)
    except (OSError, ValueError, ET.ParseError):
        return None
    if not len(v) or scale.shape != (3,):
        return None
    xy = v * scale[:2]
    if not np.all(np.isfinite(xy)):  # e.g. random_urdfs/168's mesh holds "v nan nan nan" rows: no prediction
        return None
    return np.array([xy.min(axis=0), xy.max(axis=0)])


class Randomizer:
    """Domain randomisation of one :class:`SimWorld` (all changes through ``sim.client``)."""

    def __init__(self, sim, rng: np.random.Generator, tmpdir: Path, distractors: tuple[int, int] = (2, 8)) -> None:
        import pybullet as p

        self.p, self.sim, self.rng, self.cid = p, sim, rng, sim.client
        self.tmpdir = Path(tmpdir)
        self.n_distractors = distractors
        self.distractor_bodies: list[int] = []
        self.distractor_discs: list[tuple[float, float, float]] = []
        self._tex_count = 0
        self.original_rgba = {
            b: tuple(p.getVisualShapeData(b, physicsClientId=self.cid)[0][7])
            for ids in sim.object_body_ids.values()
            for b in ids
            if p.getVisualShapeData(b, physicsClientId=self.cid)
        }
        import pybullet_data

        self.urdfs = _distractor_urdfs(pybullet_data.getDataPath())
        #: the world's ``(xmin, ymin, xmax, ymax)``, once (every viewpoint and distractor draw reads it)
        self.bounds = sim.world.bounds()
        self._blocking = None
        # the floor's and the walls' quads as OBJ text, made once a world (each re-randomisation only gives them
        # a new material); their textured meshes are made by randomize_scene
        self.floor_mesh = quad_obj_geometry(self._floor_quads())
        self.wall_mesh = quad_obj_geometry(self._wall_quads())
        self.floor_overlay: int | None = None
        self.wall_overlay: int | None = None

    # -- overlays (textured surfaces) --------------------------------------------------------
    def _floor_quads(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, float]]:
        xmin, ymin, xmax, ymax = self.bounds
        o = np.array([xmin - 1, ymin - 1, 0.0008])
        return [(o, np.array([xmax - xmin + 2, 0, 0]), np.array([0, ymax - ymin + 2, 0]), 1.0)]

    def _wall_quads(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, float]]:
        quads = []
        for wall in self.sim.world.walls:
            c, s = math.cos(wall.yaw), math.sin(wall.yaw)
            d = np.array([c, s, 0.0])
            nrm = np.array([-s, c, 0.0])
            for s0, s1, z0, z1, th, _ in wall.boxes():
                for side in (1.0, -1.0):
                    base = np.array([*wall.point_at(s0), z0]) + side * nrm * (th / 2 + 0.002)
                    u = d * (s1 - s0)
                    v = np.array([0, 0, z1 - z0])
                    # outward normal: u × v must point along side·nrm
                    if np.dot(np.cross(u, v), side * nrm) < 0:
                        quads.append((base + u, -u, v, 1.0))
                    else:
                        quads.append((base, u, v, 1.0))
        return quads

    def _overlay(self, old: int | None, mesh: str, kinds: Sequence[str]) -> int | None:
        """A new textured overlay body of the OBJ ``mesh`` text (:func:`quad_obj_geometry`; removing ``old``): a texture of one of ``kinds``
        drawn now, named by the overlay's own material file. The EGL plugin numbers textures on its own,
        so a ``textureUniqueId`` given to ``changeVisualShape`` shows the wrong one (or none) there; a
        texture read with its mesh is right in both renderers (TinyRenderer: the same pixels)."""
        p, cid = self.p, self.cid
        if old is not None:
            p.removeBody(old, physicsClientId=cid)
        if not mesh:
            return None
        img = make_texture(str(self.rng.choice(list(kinds))), self.rng)
        k = self._tex_count
        self._tex_count += 1
        # stored, not compressed: a temporary file read once by pybullet (the same pixels, 1 ms less)
        cv2.imwrite(str(self.tmpdir / f"tex{k}.png"), img[:, :, ::-1], list(PNG_STORED))
        (self.tmpdir / f"overlay{k}.mtl").write_text(f"newmtl m\nKd 1 1 1\nmap_Kd tex{k}.png\n")
        obj = write_mesh_obj(mesh, self.tmpdir / f"overlay{k}.obj", material=f"overlay{k}.mtl")
        vs = p.createVisualShape(p.GEOM_MESH, fileName=str(obj), physicsClientId=cid)
        return p.createMultiBody(0, -1, vs, [0, 0, 0], flags=body_flags(p), physicsClientId=cid)

    # -- scene -------------------------------------------------------------------------------
    def randomize_scene(self) -> None:
        p, cid, rng = self.p, self.cid, self.rng
        # floor and walls: a texture (or plain colour) on the overlays
        self.floor_overlay = self._overlay(self.floor_overlay, self.floor_mesh, TEXTURE_KINDS)
        self.wall_overlay = self._overlay(self.wall_overlay, self.wall_mesh, ("plain", "plain", "stripes", "tiles", "marble", "carpet"))
        # object colours: jitter every part around its catalogue colour, sometimes a bold new hue
        for b, rgba in self.original_rgba.items():
            if rng.random() < 0.12:
                rgb = _hsv(rng.random(), rng.uniform(0.2, 0.9), rng.uniform(0.25, 0.95))
            else:
                import colorsys

                h, s, v = colorsys.rgb_to_hsv(*[min(max(c, 0.0), 1.0) for c in rgba[:3]])
                rgb = _hsv(h + rng.uniform(-0.04, 0.04), s * rng.uniform(0.7, 1.3), v * rng.uniform(0.7, 1.25))
            p.changeVisualShape(b, -1, rgbaColor=[*rgb, 1.0], physicsClientId=cid)
        self._place_distractors()

    def _blocking_union(self):
        if self._blocking is None:
            from shapely.ops import unary_union

            self._blocking = unary_union([g for _, g in self.sim.world.blocking_geometry()])
        return self._blocking

    def _place_distractors(self) -> None:
        p, cid, rng = self.p, self.cid, self.rng
        for b in self.distractor_bodies:
            p.removeBody(b, physicsClientId=cid)
        self.distractor_bodies, self.distractor_discs = [], []
        if not self.urdfs or self.n_distractors[1] <= 0:
            return
        from shapely.geometry import Point

        blocking = self._blocking_union()
        xmin, ymin, xmax, ymax = self.bounds
        want = int(rng.integers(self.n_distractors[0], self.n_distractors[1] + 1))

        def misfit(cx: float, cy: float, r: float, slack: float = 0.0) -> bool:
            """A disc of radius ``r`` at ``(cx, cy)`` is too big, touches the blocking geometry or another
            distractor (``slack``: a radius error allowed to a prediction)."""
            return r > 0.6 or blocking.intersects(Point(cx, cy).buffer(r + 0.05 - slack)) or any(
                math.hypot(cx - dx, cy - dy) < r + dr - slack for dx, dy, dr in self.distractor_discs
            )

        tries = 0
        while len(self.distractor_bodies) < want and tries < want * 8:
            tries += 1
            urdf = self.urdfs[int(rng.integers(len(self.urdfs)))]
            scale = float(rng.uniform(2.0, 7.0))
            x, y = rng.uniform(xmin, xmax), rng.uniform(ymin, ymax)
            yaw = rng.uniform(-math.pi, math.pi)
            box = urdf_mesh_box(str(urdf))
            if box is not None:  # its disc before loading it: the same centre, a radius no larger
                c, s = math.cos(yaw), math.sin(yaw)
                mx, my = scale * (box[0] + box[1]) / 2
                hx, hy = scale * (box[1] - box[0]) / 2
                r = math.hypot(abs(c) * hx + abs(s) * hy, abs(s) * hx + abs(c) * hy)
                if misfit(x + c * mx - s * my, y + s * mx + c * my, r, slack=1e-6):
                    continue  # loading it would turn it down too
            q = p.getQuaternionFromEuler([0, 0, yaw])
            try:
                b = p.loadURDF(
                    str(urdf), [x, y, 0.0], q, globalScaling=scale, useFixedBase=True, flags=body_flags(p), physicsClientId=cid
                )
            except Exception:
                continue
            lo, hi = p.getAABB(b, -1, physicsClientId=cid)
            for j in range(p.getNumJoints(b, physicsClientId=cid)):
                a0, a1 = p.getAABB(b, j, physicsClientId=cid)
                lo, hi = np.minimum(lo, a0), np.maximum(hi, a1)
            r = 0.5 * math.hypot(hi[0] - lo[0], hi[1] - lo[1])
            cx, cy = (lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2
            if misfit(cx, cy, r):
                p.removeBody(b, physicsClientId=cid)
                continue
            pos, orn = p.getBasePositionAndOrientation(b, physicsClientId=cid)
            p.resetBasePositionAndOrientation(b, [pos[0], pos[1], pos[2] - lo[2]], orn, physicsClientId=cid)
            for j in range(-1, p.getNumJoints(b, physicsClientId=cid)):
                rgb = _hsv(rng.random(), rng.uniform(0.0, 0.9), rng.uniform(0.2, 0.95))
                p.changeVisualShape(b, j, rgbaColor=[*rgb, 1.0], physicsClientId=cid)
            self.distractor_bodies.append(b)
            self.distractor_discs.append((cx, cy, r))

    def free_for_camera(self, x: float, y: float) -> bool:
        return self.sim.pose_free(x, y) and all(math.hypot(x - dx, y - dy) > dr + 0.15 for dx, dy, dr in self.distractor_discs)

    def sample_light(self) -> dict[str, Any]:
        rng = self.rng
        az, el = rng.uniform(-math.pi, math.pi), rng.uniform(0.35, 1.45)
        warm = rng.uniform(-0.12, 0.12)
        return dict(
            lightDirection=[math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)],
            lightColor=[1.0 + warm, 1.0, 1.0 - warm],
            lightAmbientCoeff=float(rng.uniform(0.35, 0.8)),
            lightDiffuseCoeff=float(rng.uniform(0.2, 0.7)),
            lightSpecularCoeff=float(rng.uniform(0.0, 0.3)),
            shadow=int(rng.random() < 0.2),
        )


def sensor_effects(rgb: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Camera-like degradations of an (H, W, 3) uint8 image: exposure/contrast/gamma and colour balance
    (one 256-entry table per channel: they act on each pixel value alone), blur or motion blur, then
    Gaussian noise (OpenCV's generator, seeded from ``rng``: a third of numpy's time for the same draw)."""
    gain = rng.uniform(0.75, 1.25) * rng.uniform(0.93, 1.07, 3)
    contrast, gamma = rng.uniform(0.8, 1.2), rng.uniform(0.8, 1.25)
    levels = np.arange(256, dtype=np.float32)[:, None] / 255.0
    lut = np.clip(np.clip((levels - 0.5) * contrast + 0.5, 0, 1) * gain.astype(np.float32), 0, 1) ** gamma
    img = cv2.LUT(np.ascontiguousarray(rgb, dtype=np.uint8), lut.astype(np.float32).reshape(1, 256, 3))
    r = rng.random()
    if r < 0.25:
        img = cv2.GaussianBlur(img, (0, 0), rng.uniform(0.4, 1.2))
    elif r < 0.35:
        k = int(rng.integers(3, 8))
        kernel = np.zeros((k, k), np.float32)
        kernel[k // 2, :] = 1.0 / k
        if rng.random() < 0.3:
            kernel = kernel.T
        img = cv2.filter2D(img, -1, kernel)
    sigma = rng.uniform(0.5, 7.0) / 255.0
    noise = np.empty(img.shape, np.float32)
    cv2.setRNGSeed(int(rng.integers(2**31)))
    cv2.randn(noise.reshape(img.shape[0], -1), 0.0, sigma)  # one channel: randn's scalars are per channel
    return np.clip((img + noise) * 255.0 + 0.5, 0, 255).astype(np.uint8)
