"""The simulated 2D LIDAR: one sweep of ``lidar.beams`` rays over 360° from the ``base_scan`` frame.

Two casters (``lidar.caster``): ``planar`` (:class:`PlanarCaster`: the rays cast in 2D against the exact
cross-section of every collision shape at the LIDAR's height; the world is static, so the cross-section
is cut once) and ``pybullet`` (one ``rayTestBatch`` against the world bodies). The planar caster is used
while the LIDAR is level; a tilted LIDAR always falls back to pybullet's 3D rays.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.ocslam.messages import LaserScan
from app.sim.building import G_WORLD

__all__ = ["Lidar", "PlanarCaster"]


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
        from scipy.spatial import ConvexHull, QhullError

        try:
            hull = ConvexHull(pts)
        except (QhullError, ValueError):  # fewer than three distinct points, or all on one line
            return None
        if hull.volume <= 0:  # (a 2D hull's "volume" is its area)
            return None
        return np.ascontiguousarray(pts[hull.vertices])  # counter-clockwise, as qhull orders 2D hulls

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


class Lidar:
    """The robot's LIDAR in a pybullet client: ranges from ``base_scan`` with Gaussian noise.

    ``world_bodies``: the body ids the rays can hit (walls, obstacles, objects; not the floor, not the
    robot). The planar cross-section is cut at the first scan (and again if the LIDAR's height changes).
    """

    def __init__(self, p: Any, client: int, world_bodies: set[int]) -> None:
        self._p = p
        self.client = client
        self.world_bodies = world_bodies
        self._planar: PlanarCaster | None = None  # the LIDAR plane's outlines, built at the first scan

    def scan(self, T_world_scan: NDArray[np.float64], c: Any, rng: np.random.Generator, stamp: float) -> LaserScan:
        """One sweep from the ``(4, 4)`` pose ``T_world_scan`` of ``base_scan``, ``c`` the ``lidar`` config
        section: ``beams`` rays over 360° from -π, Gaussian range noise from ``rng``, ``inf`` for no return
        within ``range_max``, ``-inf`` for a return closer than ``range_min``."""
        p, cid = self._p, self.client
        n = int(c.beams)
        T = T_world_scan
        inc = 2.0 * math.pi / n
        ang = -math.pi + inc * np.arange(n)
        origin = T[:3, 3]
        if getattr(c, "caster", "planar") == "planar" and abs(T[2, 2] - 1.0) < 1e-9:
            if self._planar is None or abs(self._planar.z - origin[2]) > 1e-9:
                self._planar = PlanarCaster(p, cid, self.world_bodies, float(origin[2]))
            ranges = self._planar.cast(origin[:2], ang + math.atan2(T[1, 0], T[0, 0]), float(c.range_max_m))
        else:
            d_local = np.stack([np.cos(ang), np.sin(ang), np.zeros(n)], axis=1)
            d_world = d_local @ T[:3, :3].T
            to = origin + d_world * c.range_max_m
            frm = np.broadcast_to(origin, to.shape)
            res = p.rayTestBatch(frm.tolist(), to.tolist(), collisionFilterMask=G_WORLD, physicsClientId=cid)
            frac = np.fromiter((h[2] if h[0] >= 0 else np.inf for h in res), dtype=np.float64, count=n)
            ranges = frac * c.range_max_m
        hit = np.isfinite(ranges)
        if c.noise_std_m > 0:
            ranges[hit] += rng.normal(0.0, c.noise_std_m, int(hit.sum()))
        with np.errstate(invalid="ignore"):
            ranges[hit & (ranges > c.range_max_m)] = np.inf
            ranges[hit & (ranges < c.range_min_m)] = -np.inf
        return LaserScan(
            stamp=stamp,
            angle_min=-math.pi,
            angle_increment=inc,
            range_min=float(c.range_min_m),
            range_max=float(c.range_max_m),
            ranges=ranges,
            frame_id="base_scan",
        )
