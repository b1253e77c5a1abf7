"""Fixtures: the door (fills a wall opening), a painting on the wall and the floor beacon.

Example:
    >>> door_model().in_wall
    True
"""

from __future__ import annotations

from app.world.models.parts import (
    PI,
    ModelSpec,
    box,
    cyl,
    hex_rgb,
)


def door_model() -> ModelSpec:
    # In a wall opening 1.0 m wide and 2.1 m high; frame as deep as the wall (0.3 m).
    parts = [
        box((0.3, 0.06, 2.1), (0.0, 0.47, 1.05), "frame"),
        box((0.3, 0.06, 2.1), (0.0, -0.47, 1.05), "frame"),
        box((0.3, 1.0, 0.06), (0.0, 0.0, 2.07), "frame"),
        box((0.04, 0.88, 2.02), (0.0, 0.0, 1.01), "panel"),
    ]
    for sx in (1.0, -1.0):
        for zc in (1.45, 0.55):
            parts.append(box((0.008, 0.3, 0.7), (sx * 0.022, 0.19, zc), "trim"))
            parts.append(box((0.008, 0.3, 0.7), (sx * 0.022, -0.19, zc), "trim"))
        parts.append(cyl(0.028, 0.012, (sx * 0.026, 0.36, 1.0), "metal", rpy=(0, PI / 2, 0)))
        parts.append(cyl(0.01, 0.11, (sx * 0.045, 0.32, 1.0), "metal", rpy=(PI / 2, 0, 0)))
    return ModelSpec(
        "door",
        "door",
        tuple(parts),
        {"frame": hex_rgb("e8e4dc"), "panel": hex_rgb("8a5a35"), "trim": hex_rgb("7a4e2d"), "metal": hex_rgb("c0c0c8")},
        "panel",
        palette=(hex_rgb("8a5a35"), hex_rgb("f2f0eb"), hex_rgb("5c3b22"), hex_rgb("9aa5ad"), hex_rgb("2f4858"), hex_rgb("c19a6b")),
        in_wall=True,
        description="closed door (panel 0.88 × 2.02 m) in a 0.3 m deep frame; fills a wall opening 1.0 × 2.1 m",
    )


def painting_model() -> ModelSpec:
    parts = (box((0.03, 0.8, 0.6), (0, 0, 1.5), "frame"), box((0.01, 0.7, 0.5), (0.016, 0, 1.5), "canvas"))
    return ModelSpec("painting", None, parts, {"frame": hex_rgb("3e2c1c"), "canvas": hex_rgb("4f86c6")}, "canvas",
                     palette=(hex_rgb("4f86c6"), hex_rgb("e76f51"), hex_rgb("2a9d8f"), hex_rgb("e9c46a"), hex_rgb("8d6cab")),
                     description="framed picture 0.8 × 0.6 m hanging at 1.2–1.8 m (invisible to the LIDAR)")


def beacon_model() -> ModelSpec:
    parts = (cyl(0.05, 0.08, (0, 0, 0.04), "body"), cyl(0.02, 0.02, (0, 0, 0.09), "top"))
    return ModelSpec("beacon", None, parts, {"body": hex_rgb("2b2b2b"), "top": hex_rgb("8a8a8a")}, "body",
                     description="iRobot virtual-wall beacon Ø 0.1 m, 0.1 m tall (below the LIDAR plane)")
