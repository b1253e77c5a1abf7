"""Furniture models: tables, chairs, sofas, shelves, kitchen counter, fridge, stool, TV stand.

Each function builds one :class:`~app.world.models.parts.ModelSpec`; legged furniture is built
leg by leg, so LIDAR rays meet the legs, not the bounding box. :mod:`app.world.models.catalogue`
collects them.

Example:
    >>> table_model().label
    'table'
"""

from __future__ import annotations

import math

import numpy as np

from app.world.models.parts import (
    PI,
    ModelSpec,
    Part,
    box,
    cyl,
    hex_rgb,
    mesh,
)


def table_model() -> ModelSpec:
    # Webots 'Table' convention: 1.0 m along x, 1.8 m along y, 0.74 m high, 0.1 m square legs.
    wood = "pybullet_data:table/table.obj"
    parts = [mesh(wood, (1.0, 1.8, 0.04), (0.0, 0.0, 0.72), "top", collision="box")]
    for x in (0.45, -0.45):
        for y in (0.85, -0.85):
            parts.append(mesh(wood, (0.1, 0.1, 0.70), (x, y, 0.35), "legs", collision="box"))
    return ModelSpec(
        "table",
        "table",
        tuple(parts),
        {"top": (1.0, 1.0, 1.0), "legs": (0.92, 0.92, 0.92)},
        "top",
        palette=((1.0, 1.0, 1.0), (0.75, 0.6, 0.5), (0.55, 0.4, 0.32), (0.9, 0.85, 0.8)),
        legged=True,
        description="dining table 1.0 × 1.8 × 0.74 m with 4 legs (pybullet_data wood texture, tinted by the colour)",
    )


def round_table_model() -> ModelSpec:
    parts = (
        cyl(0.5, 0.035, (0, 0, 0.7325), "top"),
        cyl(0.04, 0.68, (0, 0, 0.37), "legs"),
        cyl(0.25, 0.03, (0, 0, 0.015), "legs"),
    )
    return ModelSpec(
        "round_table",
        "table",
        parts,
        {"top": hex_rgb("b08d6a"), "legs": hex_rgb("3a3a3a")},
        "top",
        palette=(hex_rgb("b08d6a"), hex_rgb("f0f0f0"), hex_rgb("6b4a32"), hex_rgb("d8c3a5")),
        description="round pedestal table, Ø 1.0 m, 0.75 m high (one central column at LIDAR height)",
    )


def dining_chair_model() -> ModelSpec:
    parts = []
    for x in (0.19, -0.19):
        for y in (0.19, -0.19):
            parts.append(box((0.035, 0.035, 0.45), (x, y, 0.225), "legs"))
    parts += [
        box((0.44, 0.44, 0.04), (0.0, 0.0, 0.47), "seat"),
        box((0.035, 0.035, 0.45), (-0.19, 0.19, 0.715), "legs"),
        box((0.035, 0.035, 0.45), (-0.19, -0.19, 0.715), "legs"),
        box((0.03, 0.40, 0.22), (-0.19, 0.0, 0.82), "seat"),
    ]
    return ModelSpec(
        "dining_chair",
        "chair",
        tuple(parts),
        {"legs": hex_rgb("6b4a32"), "seat": hex_rgb("a0522d")},
        "seat",
        palette=(hex_rgb("a0522d"), hex_rgb("2f4f4f"), hex_rgb("d2b48c"), hex_rgb("8b0000"), hex_rgb("f5f5f5"), hex_rgb("556b2f")),
        legged=True,
        description="dining chair, seat 0.44 × 0.44 m at 0.47 m, back 0.94 m; four legs",
    )


def sofa_model(name: str, width: float, n: int, description: str) -> ModelSpec:
    d = 1.0
    parts: list[Part] = []
    for x in (d / 2 - 0.06, -d / 2 + 0.06):
        for y in (width / 2 - 0.06, -width / 2 + 0.06):
            parts.append(cyl(0.03, 0.1, (x, y, 0.05), "feet"))
    parts += [
        box((d, width, 0.25), (0.0, 0.0, 0.225), "fabric"),
        mesh("rounded_box.obj", (0.22, width, 0.45), (-d / 2 + 0.11, 0.0, 0.575), "fabric"),
        mesh("rounded_box.obj", (d, 0.18, 0.27), (0.0, width / 2 - 0.09, 0.485), "fabric"),
        mesh("rounded_box.obj", (d, 0.18, 0.27), (0.0, -width / 2 + 0.09, 0.485), "fabric"),
    ]
    inner = width - 0.36
    cw = inner / n
    for i in range(n):
        y = -inner / 2 + cw * (i + 0.5)
        parts.append(mesh("rounded_box.obj", (d - 0.24, cw - 0.015, 0.13), (0.1, y, 0.415), "cushion"))
        parts.append(mesh("rounded_box.obj", (0.14, cw - 0.015, 0.3), (-d / 2 + 0.29, y, 0.63), "cushion", rpy=(0, -0.12, 0)))
    return ModelSpec(
        name,
        "chair",
        tuple(parts),
        {"feet": hex_rgb("2b1d14"), "fabric": hex_rgb("5a6b7d"), "cushion": hex_rgb("6f8196")},
        "fabric",
        palette=(hex_rgb("5a6b7d"), hex_rgb("7a5c45"), hex_rgb("3f5e4a"), hex_rgb("8c2f39"), hex_rgb("b8a98f"), hex_rgb("4b4b4b")),
        description=description,
    )


_BOOK_COLORS = [hex_rgb(h) for h in ("8e2424", "1f4e79", "2e7d32", "c9a227", "5d4037", "6a1b9a", "e0e0e0", "37474f", "ad1457")]


def bookshelf_model() -> ModelSpec:
    # Webots 'cabinet' bookshelf: 1.0 wide (y), 0.4 deep (x), 2.32 high; open toward +x.
    parts = [
        box((0.02, 1.0, 2.32), (-0.19, 0.0, 1.16), "wood"),
        box((0.4, 0.02, 2.32), (0.0, 0.49, 1.16), "wood"),
        box((0.4, 0.02, 2.32), (0.0, -0.49, 1.16), "wood"),
        box((0.02, 0.96, 0.08), (0.18, 0.0, 0.04), "wood"),
    ]
    for z in (0.09, 0.52, 0.96, 1.40, 1.84, 2.31):
        parts.append(box((0.38, 0.96, 0.02), (0.01, 0.0, z), "wood"))
    rng = np.random.default_rng(7)  # fixed: the books are part of the model
    for shelf_z in (0.53, 0.97, 1.41, 1.85):
        y = -0.46 + float(rng.uniform(0.0, 0.15))
        while True:
            w = float(rng.uniform(0.03, 0.06))
            h = float(rng.uniform(0.2, 0.34))
            if y + w > 0.46:
                break
            k = int(rng.integers(len(_BOOK_COLORS)))
            parts.append(box((float(rng.uniform(0.18, 0.26)), w - 0.004, h), (-0.05, y + w / 2, shelf_z + h / 2), f"book{k}"))
            y += w
            if rng.random() < 0.12:
                y += float(rng.uniform(0.05, 0.2))
    colors = {"wood": hex_rgb("a47551")}
    colors.update({f"book{k}": c for k, c in enumerate(_BOOK_COLORS)})
    return ModelSpec(
        "bookshelf",
        "shelf",
        tuple(parts),
        colors,
        "wood",
        palette=(hex_rgb("a47551"), hex_rgb("f2efe9"), hex_rgb("5c4033"), hex_rgb("d9b99b"), hex_rgb("333333")),
        description="open bookshelf 1.0 × 0.4 × 2.32 m with books; the LIDAR sees a U (back and sides)",
    )


def low_shelf_model() -> ModelSpec:
    parts = [
        box((0.35, 0.02, 1.1), (0.0, 0.59, 0.55), "wood"),
        box((0.35, 0.02, 1.1), (0.0, -0.59, 0.55), "wood"),
        box((0.02, 1.2, 1.1), (-0.165, 0.0, 0.55), "wood"),
        box((0.02, 0.4, 1.06), (0.0, 0.0, 0.55), "wood"),
    ]
    for z in (0.04, 0.38, 0.72, 1.09):
        parts.append(box((0.35, 1.2, 0.025), (0.0, 0.0, z), "wood"))
    rng = np.random.default_rng(11)
    for z0 in (0.4, 0.74):
        for side in (-1, 1):
            y = side * 0.05
            for _ in range(int(rng.integers(4, 8))):
                w = float(rng.uniform(0.03, 0.06))
                h = float(rng.uniform(0.18, 0.28))
                k = int(rng.integers(len(_BOOK_COLORS)))
                parts.append(box((0.2, w - 0.004, h), (-0.04, y + side * w / 2, z0 + h / 2), f"book{k}"))
                y += side * w
    colors = {"wood": hex_rgb("f2efe9")}
    colors.update({f"book{k}": c for k, c in enumerate(_BOOK_COLORS)})
    return ModelSpec(
        "low_shelf",
        "shelf",
        tuple(parts),
        colors,
        "wood",
        palette=(hex_rgb("f2efe9"), hex_rgb("a47551"), hex_rgb("333333"), hex_rgb("7a8b99")),
        description="low two-column bookcase 1.2 × 0.35 × 1.1 m",
    )


# -- unclassified models ----------------------------------------------------------------------


def fridge_model() -> ModelSpec:
    parts = (
        box((0.66, 0.7, 1.8), (-0.02, 0.0, 0.9), "body"),
        box((0.04, 0.68, 1.1), (0.33, 0.0, 1.235), "doors"),
        box((0.04, 0.68, 0.62), (0.33, 0.0, 0.36), "doors"),
        box((0.03, 0.03, 0.4), (0.365, -0.28, 1.0), "metal"),
        box((0.03, 0.03, 0.3), (0.365, -0.28, 0.5), "metal"),
    )
    return ModelSpec(
        "fridge", None, parts, {"body": hex_rgb("e9ecef"), "doors": hex_rgb("f8f9fa"), "metal": hex_rgb("8d99a6")}, "body",
        palette=(hex_rgb("e9ecef"), hex_rgb("b0b7bf"), hex_rgb("343a40")),
        description="fridge 0.7 × 0.7 × 1.8 m, doors toward +x",
    )


def kitchen_counter_model() -> ModelSpec:
    L = 2.2
    parts = [
        box((0.6, L, 0.1), (-0.05, 0.0, 0.05), "plinth"),
        box((0.62, L, 0.61), (0.0, 0.0, 0.405), "cabinet"),
        box((0.7, L, 0.03), (0.0, 0.0, 0.725), "worktop"),
        box((0.02, 0.58, 0.55), (0.32, 0.0, 0.41), "oven"),
        box((0.03, 0.45, 0.02), (0.34, 0.0, 0.62), "metal"),
        box((0.5, 0.56, 0.008), (0.0, 0.0, 0.744), "oven"),
    ]
    for y in (-0.82, -0.5, 0.5, 0.82):
        parts.append(box((0.02, 0.3, 0.55), (0.32, y, 0.41), "doors"))
        parts.append(box((0.025, 0.015, 0.12), (0.34, y + (0.1 if y > 0 else -0.1), 0.58), "metal"))
    return ModelSpec(
        "kitchen_counter", None, tuple(parts),
        {"plinth": hex_rgb("2b2b2b"), "cabinet": hex_rgb("d8d2c4"), "worktop": hex_rgb("6b5b4b"), "oven": hex_rgb("151515"),
         "metal": hex_rgb("a9a9a9"), "doors": hex_rgb("efeae0")},
        "doors",
        palette=(hex_rgb("efeae0"), hex_rgb("5b7065"), hex_rgb("2f3e46"), hex_rgb("c9ada7")),
        description="kitchen run 2.2 m long (y) × 0.7 m deep, worktop at 0.74 m, oven in the middle, front toward +x",
    )


def stool_model() -> ModelSpec:
    parts = [cyl(0.17, 0.04, (0, 0, 0.47), "seat")]
    for k in range(4):
        a = PI / 4 + k * PI / 2
        parts.append(cyl(0.018, 0.46, (0.12 * math.cos(a), 0.12 * math.sin(a), 0.23), "legs"))
    return ModelSpec("stool", None, tuple(parts), {"seat": hex_rgb("7b4b2a"), "legs": hex_rgb("2b2b2b")}, "seat",
                     palette=(hex_rgb("7b4b2a"), hex_rgb("c0392b"), hex_rgb("2c3e50"), hex_rgb("f0e6d2")),
                     legged=True, description="round stool, Ø 0.34 m, four legs")


def tv_stand_model() -> ModelSpec:
    parts = (
        box((0.4, 1.2, 0.45), (0, 0, 0.225), "stand"),
        box((0.2, 0.3, 0.04), (0, 0, 0.47), "screen"),
        box((0.04, 0.06, 0.12), (0, 0, 0.55), "screen"),
        box((0.05, 1.0, 0.58), (0, 0, 0.89), "screen"),
        box((0.005, 0.94, 0.52), (0.026, 0, 0.89), "display"),
    )
    return ModelSpec("tv_stand", None, parts, {"stand": hex_rgb("4a3b30"), "screen": hex_rgb("111111"), "display": hex_rgb("1c2833")},
                     "stand", palette=(hex_rgb("4a3b30"), hex_rgb("f0f0f0"), hex_rgb("2b2b2b")),
                     description="TV on a low cabinet 1.2 × 0.4 m, screen 1.0 × 0.58 m")
