"""The small classified objects: balls, dog, gnome, rubber duck, person, extinguisher, flowers; and clutter.

Each function builds one :class:`~app.world.models.parts.ModelSpec` (sizes after the paper's
apartment, spec §5); :mod:`app.world.models.catalogue` collects them. The trash bin and the
cardboard box are unclassified clutter.

Example:
    >>> dog_model().legged
    True
"""

from __future__ import annotations

import math

import numpy as np

from app.world.models.parts import (
    COLLISION_ONLY,
    PI,
    ModelSpec,
    Part,
    box,
    caps,
    cyl,
    ell,
    hex_rgb,
    mesh,
    sph,
)


def soccer_ball_model() -> ModelSpec:
    r = 0.1125  # FIFA size 5
    p = mesh("pybullet_data:soccerball.obj", (2 * r,) * 3, (0, 0, r), "ball", collision="none")
    return ModelSpec(
        "soccer_ball",
        "ball",
        (p, Part("sphere", (r,), (0.0, 0.0, r), (0.0, 0.0, 0.0), COLLISION_ONLY)),
        {"ball": (1.0, 1.0, 1.0)},
        "ball",
        palette=((1.0, 1.0, 1.0), (1.0, 0.95, 0.75), (0.85, 0.92, 1.0), (1.0, 0.85, 0.85)),
        description="FIFA size-5 soccer ball (pybullet_data mesh, texture tinted by the colour)",
    )


def play_ball_model() -> ModelSpec:
    r = 0.11
    parts = (
        sph(r, (0, 0, r), "ball"),
        cyl(r + 0.0015, 0.035, (0, 0, r), "band"),
        cyl(r + 0.0015, 0.035, (0, 0, r), "band2", rpy=(PI / 2, 0, 0)),
    )
    return ModelSpec(
        "play_ball",
        "ball",
        parts,
        {"ball": hex_rgb("d62828"), "band": hex_rgb("f7d716"), "band2": hex_rgb("1d6fd6")},
        "ball",
        palette=(hex_rgb("d62828"), hex_rgb("2a9d8f"), hex_rgb("f77f00"), hex_rgb("6a4c93"), hex_rgb("e9c46a")),
        description="rubber play ball with two coloured bands",
    )


def dog_model() -> ModelSpec:
    parts: list[Part] = []
    for x in (0.22, -0.22):
        for y in (0.085, -0.085):
            parts.append(cyl(0.05, 0.34, (x, y, 0.19), "fur"))
            parts.append(ell((0.065, 0.05, 0.025), (x + 0.02, y, 0.025), "paws"))
    parts += [
        ell((0.32, 0.13, 0.14), (0.0, 0.0, 0.44), "fur"),
        ell((0.14, 0.12, 0.15), (0.19, 0.0, 0.45), "chest"),
        cyl(0.07, 0.2, (0.31, 0.0, 0.55), "fur", rpy=(0, 0.62, 0)),
        ell((0.12, 0.085, 0.09), (0.39, 0.0, 0.65), "fur"),
        ell((0.08, 0.045, 0.045), (0.49, 0.0, 0.62), "muzzle"),
        sph(0.02, (0.565, 0.0, 0.635), "nose"),
        sph(0.014, (0.47, 0.042, 0.68), "nose"),
        sph(0.014, (0.47, -0.042, 0.68), "nose"),
        ell((0.035, 0.015, 0.075), (0.36, 0.085, 0.63), "ears", rpy=(0.25, 0, 0)),
        ell((0.035, 0.015, 0.075), (0.36, -0.085, 0.63), "ears", rpy=(-0.25, 0, 0)),
        caps(0.025, 0.17, (-0.36, 0.0, 0.53), "fur", rpy=(0, -0.75, 0)),
    ]
    return ModelSpec(
        "dog",
        "dog",
        tuple(parts),
        {
            "fur": hex_rgb("8b5a2b"),
            "chest": hex_rgb("c8a27a"),
            "paws": hex_rgb("d9c3a5"),
            "muzzle": hex_rgb("c8a27a"),
            "nose": hex_rgb("141414"),
            "ears": hex_rgb("4a2e17"),
        },
        "fur",
        palette=(hex_rgb("8b5a2b"), hex_rgb("2b2b2b"), hex_rgb("d4a55a"), hex_rgb("e8e0d0"), hex_rgb("6b4a32"), hex_rgb("a0522d")),
        legged=True,
        description="a medium dog (≈1.0 × 0.27 × 0.75 m); legs r 0.05 m, front and rear pairs 0.44 m apart",
    )


def gnome_model() -> ModelSpec:
    parts = (
        ell((0.07, 0.045, 0.035), (0.03, 0.055, 0.035), "boots"),
        ell((0.07, 0.045, 0.035), (0.03, -0.055, 0.035), "boots"),
        cyl(0.09, 0.12, (0.0, 0.0, 0.12), "pants"),
        mesh("frustum.obj", (0.12, 0.11, 0.30), (0.0, 0.0, 0.31), "coat"),
        cyl(0.106, 0.04, (0.0, 0.0, 0.33), "belt"),
        caps(0.034, 0.15, (0.02, 0.11, 0.37), "coat", rpy=(0.35, 0.3, 0)),
        caps(0.034, 0.15, (0.02, -0.11, 0.37), "coat", rpy=(-0.35, 0.3, 0)),
        sph(0.035, (0.065, 0.1, 0.29), "skin"),
        sph(0.035, (0.065, -0.1, 0.29), "skin"),
        mesh("cone.obj", (0.085, 0.075, 0.22), (0.05, 0.0, 0.49), "beard", rpy=(PI, 0, 0)),
        sph(0.075, (0.0, 0.0, 0.575), "skin"),
        sph(0.024, (0.075, 0.0, 0.57), "nose"),
        mesh("cone.obj", (0.1, 0.1, 0.32), (-0.01, 0.0, 0.78), "hat", rpy=(0, -0.12, 0)),
    )
    return ModelSpec(
        "gnome",
        "gnome",
        parts,
        {
            "boots": hex_rgb("3b2314"),
            "pants": hex_rgb("5b7a3a"),
            "coat": hex_rgb("2456a4"),
            "belt": hex_rgb("1a1a1a"),
            "skin": hex_rgb("f1c9a5"),
            "nose": hex_rgb("e8967a"),
            "beard": hex_rgb("f2f2f2"),
            "hat": hex_rgb("c8102e"),
        },
        "hat",
        palette=(hex_rgb("c8102e"), hex_rgb("e63946"), hex_rgb("2a9d8f"), hex_rgb("1d3557"), hex_rgb("8338ec")),
        description="garden gnome (≈0.27 × 0.24 m footprint, 0.94 m tall)",
    )


def rubber_duck_model() -> ModelSpec:
    s = 0.065  # the pybullet_data duck scaled to 0.11 × 0.075 × 0.10 m, head toward +x
    p = mesh(
        "pybullet_data:duck.obj",
        (s, s, s),
        (-0.0087, -0.0024, -0.0065),
        "duck",
        rpy=(PI / 2, 0, PI),
        collision="pybullet_data:duck_vhacd.obj",
    )
    return ModelSpec(
        "rubber_duck",
        "duck",
        (p,),
        {"duck": (1.0, 1.0, 1.0)},
        "duck",
        palette=((1.0, 1.0, 1.0), (1.0, 0.9, 0.6), (1.0, 0.8, 0.8), (0.85, 1.0, 0.85)),
        description="rubber duck (pybullet_data mesh, 0.11 × 0.075 × 0.10 m): below the LIDAR plane",
    )


def person_model() -> ModelSpec:
    parts = []
    for y in (0.116, -0.116):
        parts += [
            box((0.26, 0.1, 0.07), (0.04, y, 0.035), "shoes"),
            cyl(0.07, 0.45, (0.0, y, 0.295), "pants"),
            cyl(0.085, 0.45, (0.0, y * 0.92, 0.73), "pants"),
        ]
    for s in (1.0, -1.0):
        parts += [
            caps(0.05, 0.24, (0.0, s * 0.255, 1.36), "shirt", rpy=(s * 0.08, 0, 0)),
            caps(0.042, 0.22, (0.02, s * 0.27, 1.1), "skin", rpy=(s * 0.02, -0.1, 0)),
            sph(0.05, (0.035, s * 0.272, 0.93), "skin"),
            sph(0.012, (0.09, s * 0.032, 1.69), "hair"),
        ]
    parts += [
        box((0.22, 0.36, 0.15), (0.0, 0.0, 0.95), "pants"),
        mesh("rounded_box.obj", (0.24, 0.42, 0.52), (0.0, 0.0, 1.28), "shirt"),
        cyl(0.05, 0.08, (0.0, 0.0, 1.57), "skin"),
        ell((0.095, 0.085, 0.115), (0.0, 0.0, 1.67), "skin"),
        ell((0.1, 0.09, 0.075), (-0.015, 0.0, 1.74), "hair"),
    ]
    return ModelSpec(
        "person",
        "person",
        tuple(parts),
        {"shoes": hex_rgb("222222"), "pants": hex_rgb("2d3e5e"), "shirt": hex_rgb("c0392b"), "skin": hex_rgb("e0b08f"), "hair": hex_rgb("3b2a1a")},
        "shirt",
        palette=(hex_rgb("c0392b"), hex_rgb("27ae60"), hex_rgb("2980b9"), hex_rgb("f1c40f"), hex_rgb("ecf0f1"), hex_rgb("8e44ad"), hex_rgb("34495e")),
        legged=True,
        description="standing person, 1.8 m, facing +x; lower legs r 0.07 m at y = ±0.116 m",
    )


def extinguisher_model() -> ModelSpec:
    parts = (
        cyl(0.092, 0.03, (0, 0, 0.015), "black"),
        cyl(0.09, 0.56, (0, 0, 0.31), "red"),
        cyl(0.0915, 0.16, (0, 0, 0.33), "label"),
        ell((0.09, 0.09, 0.06), (0, 0, 0.59), "red"),
        cyl(0.03, 0.05, (0, 0, 0.665), "metal"),
        box((0.07, 0.05, 0.05), (0, 0, 0.71), "metal"),
        box((0.16, 0.025, 0.012), (0.03, 0, 0.752), "black", rpy=(0, -0.2, 0)),
        box((0.12, 0.025, 0.012), (0.02, 0, 0.726), "black"),
        caps(0.013, 0.42, (-0.105, 0, 0.47), "black"),
        cyl(0.018, 0.06, (-0.105, 0, 0.23), "black"),
    )
    return ModelSpec(
        "fire_extinguisher",
        "extinguisher",
        parts,
        {"black": hex_rgb("1a1a1a"), "red": hex_rgb("c1121f"), "label": hex_rgb("f0f0f0"), "metal": hex_rgb("9a9a9a")},
        "red",
        palette=(hex_rgb("c1121f"), hex_rgb("d62828"), hex_rgb("a4161a"), hex_rgb("e5383b")),
        description="fire extinguisher, cylinder r 0.09 m, 0.76 m tall, with hose",
    )


def flowers_model() -> ModelSpec:
    parts = [
        mesh("frustum.obj", (0.085, 0.085, 0.22), (0, 0, 0.11), "pot", rpy=(PI, 0, 0)),
        cyl(0.09, 0.025, (0, 0, 0.21), "pot"),
        cyl(0.078, 0.01, (0, 0, 0.22), "soil"),
    ]
    stems = [  # (top x, top y, top z, head yaw)
        (0.03, 0.0, 0.9, 0.0),
        (-0.02, 0.05, 0.78, 1.0),
        (0.0, -0.05, 0.66, -0.9),
    ]
    for i, (tx, ty, tz, yaw) in enumerate(stems):
        base = np.array([0.0, 0.0, 0.22])
        top = np.array([tx, ty, tz])
        d = top - base
        length = float(np.linalg.norm(d))
        pitch = float(math.atan2(math.hypot(d[0], d[1]), d[2]))
        az = float(math.atan2(d[1], d[0]))
        mid = (base + top) / 2
        parts.append(cyl(0.008, length, tuple(mid), "stem", rpy=(0, pitch, az)))
        for k, frac in enumerate((0.35, 0.6)):
            p = base + d * frac
            side = 1.0 if (i + k) % 2 == 0 else -1.0
            parts.append(
                ell((0.065, 0.028, 0.006), (p[0] + side * 0.03 * math.sin(yaw + 1), p[1] + side * 0.03 * math.cos(yaw + 1), p[2]),
                    "leaf", rpy=(0.3 * side, -0.4, yaw + side * 1.2))
            )
        # the head faces outward along `yaw`, tilted 0.45 rad up
        n = np.array([math.cos(yaw) * math.cos(0.45), math.sin(yaw) * math.cos(0.45), math.sin(0.45)])
        hp = top + n * 0.01
        rpy = (0.0, PI / 2 - 0.45, yaw)
        parts.append(mesh("flower_head.obj", (0.09, 0.09, 0.2), tuple(hp), "petals", rpy=rpy))
        parts.append(cyl(0.038, 0.022, tuple(hp + n * 0.008), "seeds", rpy=rpy))
    return ModelSpec(
        "potted_flowers",
        "flowers",
        tuple(parts),
        {
            "pot": hex_rgb("b5542d"),
            "soil": hex_rgb("3b2a1a"),
            "stem": hex_rgb("4f7f2a"),
            "leaf": hex_rgb("3f8f2f"),
            "petals": hex_rgb("f5c400"),
            "seeds": hex_rgb("4a2c12"),
        },
        "petals",
        palette=(hex_rgb("f5c400"), hex_rgb("ff8c00"), hex_rgb("e63946"), hex_rgb("ff69b4"), hex_rgb("f8f8f8"), hex_rgb("9b5de5")),
        description="three sunflowers in a terracotta pot (pot 0.17 m, 0.95 m tall)",
    )


def trash_bin_model() -> ModelSpec:
    parts = (cyl(0.15, 0.42, (0, 0, 0.21), "body"), cyl(0.155, 0.03, (0, 0, 0.435), "lid"))
    return ModelSpec("trash_bin", None, parts, {"body": hex_rgb("6c757d"), "lid": hex_rgb("343a40")}, "body",
                     palette=(hex_rgb("6c757d"), hex_rgb("2a9d8f"), hex_rgb("e9c46a"), hex_rgb("264653")),
                     description="pedal bin Ø 0.3 m, 0.45 m tall")


def cardboard_box_model() -> ModelSpec:
    parts = (box((0.45, 0.35, 0.32), (0, 0, 0.16), "box"), box((0.455, 0.06, 0.005), (0, 0, 0.3205), "tape"))
    return ModelSpec("cardboard_box", None, parts, {"box": hex_rgb("b8865b"), "tape": hex_rgb("d9c8a0")}, "box",
                     palette=(hex_rgb("b8865b"), hex_rgb("a47148"), hex_rgb("c9a27e")), description="cardboard box 0.45 × 0.35 × 0.32 m")
