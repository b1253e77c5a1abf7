#!/usr/bin/env python3
"""Generate the TurtleBot3 Burger visual meshes in ``assets/meshes/turtlebot3/`` with trimesh.

The meshes are drawn from the robot's public dimensions (no downloaded robot meshes). Each file is one
part with one colour; the colours are URDF materials in ``assets/urdf/turtlebot3_burger.urdf``. Every
mesh is authored in the frame of the link that shows it (REP-103: x forward, y left, z up, metres), so
the URDF visuals need no origin offsets (except the plate, stacked four times at different heights):

- ``base_link``: origin at the wheel-axle midpoint, 0.010 m above the floor (floor at z = -0.010).
  The stacked plates are centred 0.032 m behind the axle, under the LIDAR.
- ``wheel_*_link``: origin at the wheel centre, spin axis y (one mesh, symmetric, used by both wheels).
- ``caster_back_link``: origin at the caster ball centre (ball touches the floor).
- ``base_scan``: origin at the LDS-01 scan centre, 0.173 m above the floor.
- ``camera_link``: origin at the camera's optical centre, x forward; the body lies behind x = 0 so the
  simulated camera never sees its own housing.

Output is deterministic: fixed geometry, fixed tessellation and a fixed-precision OBJ writer
(``v``/``vn``/``f`` lines only, no material library). ``tests/test_urdf.py`` regenerates the files into
a temporary folder and compares them with the committed ones.

Usage:
    python scripts/make_robot_meshes.py [--out assets/meshes/turtlebot3]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import trimesh
from shapely.geometry import Polygon, box

OUT_DEFAULT = Path(__file__).resolve().parents[1] / "assets" / "meshes" / "turtlebot3"

# --- public dimensions (metres), in base_link unless stated ---------------------------------------
FLOOR_Z = -0.010  # base_footprint -> base_link is z +0.010
BODY_CX = -0.032  # plates and LIDAR are centred 32 mm behind the wheel axle
PLATE_HALF = 0.069  # plates are 0.138 m square-ish (0.178 m total width with the wheels)
PLATE_CORNER_R = 0.030
PLATE_T = 0.004
PLATE_BOTTOMS_ABOVE_FLOOR = (0.012, 0.057, 0.103, 0.149)  # four waffle layers; the top one carries the LDS
WHEEL_R = 0.033
WHEEL_W = 0.018
WHEEL_Y = 0.080
CASTER_BALL_R = 0.006
SCAN_Z_ABOVE_FLOOR = 0.173
CAMERA_Z_ABOVE_FLOOR = 0.190
CAMERA_X = 0.030  # camera_link x in base_link
CYL_SECTIONS = 48


def _T(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> np.ndarray:
    return trimesh.transformations.translation_matrix((x, y, z))


_RX90 = trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0))  # cylinder axis z -> -y
_RY90 = trimesh.transformations.rotation_matrix(np.pi / 2, (0, 1, 0))  # cylinder axis z -> x


def _box(x0: float, x1: float, y0: float, y1: float, z0: float, z1: float) -> trimesh.Trimesh:
    c = ((x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2)
    return trimesh.creation.box(extents=(x1 - x0, y1 - y0, z1 - z0), transform=_T(*c))


def _cyl_z(r: float, z0: float, z1: float, x: float = 0.0, y: float = 0.0, sections: int = CYL_SECTIONS):
    return trimesh.creation.cylinder(
        radius=r, height=z1 - z0, sections=sections, transform=_T(x, y, (z0 + z1) / 2)
    )


def _extrude(poly: Polygon, z0: float, z1: float) -> trimesh.Trimesh:
    return trimesh.creation.extrude_polygon(poly, height=z1 - z0, transform=_T(0, 0, z0))


# --- parts ----------------------------------------------------------------------------------------
def plate() -> trimesh.Trimesh:
    """One rounded-square waffle plate with a grid of square holes, bottom face at z = 0.

    base_link x/y; the URDF stacks four copies at ``PLATE_BOTTOMS_ABOVE_FLOOR`` with visual origins.
    """
    a, r = PLATE_HALF, PLATE_CORNER_R
    outline = box(BODY_CX - a + r, -a + r, BODY_CX + a - r, a - r).buffer(r, quad_segs=6)
    holes = []
    step, hw = 0.024, 0.0065
    for i in range(-2, 3):
        for j in range(-2, 3):
            if i == 0 and j == 0:
                continue  # central cable hole is larger
            cx, cy = BODY_CX + i * step, j * step
            holes.append(box(cx - hw, cy - hw, cx + hw, cy + hw).exterior.coords)
    holes.append(box(BODY_CX - 0.011, -0.011, BODY_CX + 0.011, 0.011).exterior.coords)
    plate = Polygon(outline.exterior.coords, holes)
    return _extrude(plate, 0.0, PLATE_T)


def standoffs() -> trimesh.Trimesh:
    """Four brass/steel posts through the plate corners (base_link)."""
    z0 = FLOOR_Z + PLATE_BOTTOMS_ABOVE_FLOOR[0]
    z1 = FLOOR_Z + PLATE_BOTTOMS_ABOVE_FLOOR[-1] + PLATE_T
    d = 0.052
    return trimesh.util.concatenate(
        [_cyl_z(0.0035, z0, z1, BODY_CX + sx * d, sy * d, sections=12) for sx in (-1, 1) for sy in (-1, 1)]
    )


def motors() -> trimesh.Trimesh:
    """Two DYNAMIXEL XL430 servos on the bottom plate, shafts on the wheel axle (base_link)."""
    z0 = FLOOR_Z + PLATE_BOTTOMS_ABOVE_FLOOR[0] + PLATE_T
    parts = []
    for s in (-1, 1):
        y_out = s * (WHEEL_Y - WHEEL_W / 2 - 0.002)
        y_in = y_out - s * 0.0465
        parts.append(_box(-0.017, 0.017, min(y_in, y_out), max(y_in, y_out), z0, z0 + 0.0285))
    return trimesh.util.concatenate(parts)


def battery() -> trimesh.Trimesh:
    """LiPo pack behind the motors, on the bottom plate (base_link)."""
    z0 = FLOOR_Z + PLATE_BOTTOMS_ABOVE_FLOOR[0] + PLATE_T
    return _box(BODY_CX - 0.070 + 0.004, BODY_CX - 0.004, -0.017, 0.017, z0, z0 + 0.026)


def boards() -> trimesh.Trimesh:
    """OpenCR (layer 2) and Raspberry Pi (layer 3) boards with a few components (base_link)."""
    parts = []
    z2 = FLOOR_Z + PLATE_BOTTOMS_ABOVE_FLOOR[1] + PLATE_T
    parts.append(_box(BODY_CX - 0.052, BODY_CX + 0.052, -0.037, 0.037, z2 + 0.006, z2 + 0.0076))
    parts.append(_box(BODY_CX - 0.010, BODY_CX + 0.010, -0.010, 0.010, z2 + 0.0076, z2 + 0.011))
    z3 = FLOOR_Z + PLATE_BOTTOMS_ABOVE_FLOOR[2] + PLATE_T
    parts.append(_box(BODY_CX - 0.0425, BODY_CX + 0.0425, -0.028, 0.028, z3 + 0.006, z3 + 0.0076))
    parts.append(
        _box(BODY_CX + 0.020, BODY_CX + 0.041, -0.026, 0.026, z3 + 0.0076, z3 + 0.0236)
    )  # USB/Ethernet
    parts.append(_box(BODY_CX - 0.020, BODY_CX - 0.006, -0.007, 0.007, z3 + 0.0076, z3 + 0.0096))  # SoC
    return trimesh.util.concatenate(parts)


def wheel_tyre() -> trimesh.Trimesh:
    """Rubber tyre, spin axis y (wheel link)."""
    return trimesh.creation.annulus(r_min=0.0265, r_max=WHEEL_R, height=WHEEL_W, sections=64, transform=_RX90)


def wheel_hub() -> trimesh.Trimesh:
    """Rim disc with spokes and a hub flush with the tyre faces, spin axis y (wheel link)."""
    disc = trimesh.creation.cylinder(radius=0.0266, height=0.012, sections=64, transform=_RX90)
    hub = trimesh.creation.cylinder(radius=0.009, height=WHEEL_W, sections=24, transform=_RX90)
    spokes = [
        trimesh.creation.box(
            extents=(0.044, 0.016, 0.005),
            transform=trimesh.transformations.rotation_matrix(k * np.pi / 3, (0, 1, 0)),
        )
        for k in range(3)
    ]
    return trimesh.util.concatenate([disc, hub, *spokes])


def caster_housing() -> trimesh.Trimesh:
    """Ball-caster housing, bolted under the bottom plate (caster_back_link)."""
    top = FLOOR_Z + PLATE_BOTTOMS_ABOVE_FLOOR[0] - (FLOOR_Z + CASTER_BALL_R)  # plate underside in link frame
    return trimesh.util.concatenate(
        [_cyl_z(0.0095, 0.0015, top, sections=32), _box(-0.014, 0.014, -0.008, 0.008, top - 0.002, top)]
    )


def caster_ball() -> trimesh.Trimesh:
    """Steel ball touching the floor (caster_back_link)."""
    return trimesh.creation.icosphere(subdivisions=2, radius=CASTER_BALL_R)


def lds_base() -> trimesh.Trimesh:
    """LDS-01 fixed base with the motor bump at the back, sitting on the top plate (base_scan)."""
    z0 = FLOOR_Z + PLATE_BOTTOMS_ABOVE_FLOOR[-1] + PLATE_T - (FLOOR_Z + SCAN_Z_ABOVE_FLOOR)
    outline = box(-0.061 + 0.012, -0.0348 + 0.012, 0.035 - 0.012, 0.0348 - 0.012).buffer(0.012, quad_segs=6)
    return _extrude(outline, z0, -0.008)


def lds_turret() -> trimesh.Trimesh:
    """Spinning head: lower ring and top cap (base_scan)."""
    return trimesh.util.concatenate([_cyl_z(0.034, -0.008, -0.0045), _cyl_z(0.034, 0.0075, 0.0195)])


def lds_window() -> trimesh.Trimesh:
    """Dark window band around the scan plane z = 0 (base_scan)."""
    return _cyl_z(0.0325, -0.0045, 0.0075)


def camera_body() -> trimesh.Trimesh:
    """Compact RGB camera body behind the optical centre plus its post to the top plate (camera_link)."""
    plate_top = FLOOR_Z + PLATE_BOTTOMS_ABOVE_FLOOR[-1] + PLATE_T  # base_link z
    cam_z = FLOOR_Z + CAMERA_Z_ABOVE_FLOOR
    body = _box(-0.024, -0.002, -0.030, 0.030, -0.0125, 0.0125)
    post = _box(-0.018, -0.008, -0.005, 0.005, plate_top - cam_z, -0.0125)
    foot = _box(-0.022, -0.004, -0.010, 0.010, plate_top - cam_z, plate_top - cam_z + 0.002)
    return trimesh.util.concatenate([body, post, foot])


def camera_lens() -> trimesh.Trimesh:
    """Lens barrel, flush with the optical centre x = 0 (camera_link)."""
    return trimesh.creation.cylinder(
        radius=0.0065, height=0.004, sections=32, transform=_T(-0.002, 0, 0) @ _RY90
    )


PARTS = {
    "plate": plate,
    "standoffs": standoffs,
    "motors": motors,
    "battery": battery,
    "boards": boards,
    "wheel_tyre": wheel_tyre,
    "wheel_hub": wheel_hub,
    "caster_housing": caster_housing,
    "caster_ball": caster_ball,
    "lds_base": lds_base,
    "lds_turret": lds_turret,
    "lds_window": lds_window,
    "camera_body": camera_body,
    "camera_lens": camera_lens,
}


# --- output ---------------------------------------------------------------------------------------
def obj_text(mesh: trimesh.Trimesh, name: str) -> str:
    """Fixed-precision OBJ with per-vertex normals, split at sharp edges (> 30°) for crisp shading."""
    shaded = trimesh.graph.smooth_shade(mesh, angle=np.radians(30.0), facet_minarea=None)
    v = np.round(np.asarray(shaded.vertices, dtype=np.float64), 5) + 0.0  # + 0.0 turns -0.0 into 0.0
    n = np.round(np.asarray(shaded.vertex_normals, dtype=np.float64), 3) + 0.0
    f = np.asarray(shaded.faces, dtype=np.int64) + 1
    lines = [f"# {name}: generated by scripts/make_robot_meshes.py (OCSLAM), metres, link frame", f"o {name}"]
    lines += [f"v {a:.5f} {b:.5f} {c:.5f}" for a, b, c in v]
    lines += [f"vn {a:.3f} {b:.3f} {c:.3f}" for a, b, c in n]
    lines += [f"f {a}//{a} {b}//{b} {c}//{c}" for a, b, c in f]
    return "\n".join(lines) + "\n"


def build_meshes() -> dict[str, trimesh.Trimesh]:
    """All parts, keyed by file stem."""
    return {name: fn() for name, fn in PARTS.items()}


def write_meshes(out_dir: Path) -> list[Path]:
    """Write every part as ``out_dir/<name>.obj``; returns the written paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, mesh in build_meshes().items():
        p = out_dir / f"{name}.obj"
        p.write_text(obj_text(mesh, name), encoding="utf-8", newline="\n")
        paths.append(p)
    return paths


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=OUT_DEFAULT, help="output folder (default: %(default)s)")
    args = ap.parse_args(argv)
    paths = write_meshes(args.out)
    total = sum(p.stat().st_size for p in paths)
    for p in paths:
        print(f"{p.stat().st_size:8d}  {p}")
    print(f"{total:8d}  total bytes in {len(paths)} files")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
