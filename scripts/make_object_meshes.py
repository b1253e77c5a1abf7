#!/usr/bin/env python3
"""Write the unit meshes the object models are built from (``assets/meshes/objects/*.obj``).

Each mesh is a small, low-poly, centred unit shape; a model part scales it per axis (pybullet's
``meshScale``), so a handful of files build every non-primitive part (dog body, gnome hat, flower
pot, sunflower heads, ...). The output is deterministic: running the script twice gives identical
files. Usage::

    python scripts/make_object_meshes.py [--out assets/meshes/objects]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import trimesh

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "assets" / "meshes" / "objects"


def ellipsoid() -> trimesh.Trimesh:
    """Unit sphere (radius 1) to be scaled into ellipsoids; 16 × 10 UV segments."""
    return trimesh.creation.uv_sphere(radius=1.0, count=[16, 10])


def cone() -> trimesh.Trimesh:
    """Cone of base radius 1 and height 1, centred: base at z = -0.5, apex at z = +0.5."""
    m = trimesh.creation.cone(radius=1.0, height=1.0, sections=16)
    m.apply_translation([0.0, 0.0, -0.5])
    return m


def frustum(top_ratio: float = 0.7) -> trimesh.Trimesh:
    """Truncated cone: radius 1 at z = -0.5, ``top_ratio`` at z = +0.5 (16 sections)."""
    n = 16
    a = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    bottom = np.c_[np.cos(a), np.sin(a), np.full(n, -0.5)]
    top = np.c_[top_ratio * np.cos(a), top_ratio * np.sin(a), np.full(n, 0.5)]
    return trimesh.convex.convex_hull(np.vstack([bottom, top]))


def flower_head(petals: int = 14) -> trimesh.Trimesh:
    """A flat star (sunflower petals): outer radius 1, inner radius 0.55, thickness 0.1, centred."""
    a = np.linspace(0.0, 2.0 * np.pi, 2 * petals, endpoint=False)
    r = np.where(np.arange(2 * petals) % 2 == 0, 1.0, 0.55)
    from shapely.geometry import Polygon

    poly = Polygon(np.c_[r * np.cos(a), r * np.sin(a)])
    m = trimesh.creation.extrude_polygon(poly, height=0.1)
    m.apply_translation([0.0, 0.0, -0.05])
    return m


def rounded_box() -> trimesh.Trimesh:
    """Unit cube (side 1) with bevelled vertical edges (cushions, sofa arms): a convex octagonal prism."""
    c = 0.42
    pts = np.array([[0.5, c], [c, 0.5], [-c, 0.5], [-0.5, c], [-0.5, -c], [-c, -0.5], [c, -0.5], [0.5, -c]])
    verts = np.vstack([np.c_[pts, np.full(8, -0.5)], np.c_[pts, np.full(8, 0.5)]])
    return trimesh.convex.convex_hull(verts)


MESHES = {
    "ellipsoid": ellipsoid,
    "cone": cone,
    "frustum": frustum,
    "flower_head": flower_head,
    "rounded_box": rounded_box,
}


def write(out: Path) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, make in MESHES.items():
        mesh = make()
        mesh.vertices = np.round(mesh.vertices, 6)
        text = trimesh.exchange.obj.export_obj(mesh, include_normals=True, include_texture=False, header=None)
        path = out / f"{name}.obj"
        path.write_text(f"# OCSLAM unit mesh '{name}' (scripts/make_object_meshes.py)\n" + text, encoding="utf-8")
        paths.append(path)
    return paths


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args()
    for p in write(args.out):
        print(f"wrote {p} ({p.stat().st_size} bytes)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
