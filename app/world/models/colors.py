"""Colours: parsing world-file colours, per-instance colours of a model, random colours of generated worlds.

Example:
    >>> parse_color("#ff8000")
    (1.0, 0.5019607843137255, 0.0)
"""

from __future__ import annotations

import colorsys
import math
from collections.abc import Sequence

import numpy as np

from app.world.models.catalogue import get_model
from app.world.models.parts import RGB, ModelSpec, hex_rgb

__all__ = ["parse_color", "jitter_color", "resolve_colors", "pick_color", "FLOOR_COLORS", "WALL_COLORS"]


def parse_color(value: object) -> RGB:
    """``[r, g, b]`` in [0, 1], ``[R, G, B]`` in 0..255 (any value > 1), or ``"#rrggbb"``. ``ValueError`` otherwise."""
    if isinstance(value, str):
        h = value.strip().lstrip("#")
        if len(h) != 6:
            raise ValueError(f"colour {value!r}: expected '#rrggbb'")
        try:
            return hex_rgb(h)
        except ValueError:
            raise ValueError(f"colour {value!r}: expected '#rrggbb'") from None
    if isinstance(value, (list, tuple)) and len(value) == 3 and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) for v in value
    ):
        c = [float(v) for v in value]
        if not all(math.isfinite(v) and v >= 0 for v in c):
            raise ValueError(f"colour {value!r}: components must be finite and ≥ 0")
        if max(c) > 1.0:
            if max(c) > 255:
                raise ValueError(f"colour {value!r}: components above 255")
            c = [v / 255.0 for v in c]
        return (c[0], c[1], c[2])
    raise ValueError(f"colour {value!r}: expected [r, g, b] or '#rrggbb'")


def jitter_color(rgb: Sequence[float], rng: np.random.Generator, amount: float = 0.08) -> RGB:
    """Perturb hue, saturation and value by up to ``amount`` (hue by a quarter of it)."""
    h, s, v = colorsys.rgb_to_hsv(*[min(max(float(c), 0.0), 1.0) for c in rgb[:3]])
    h = (h + rng.uniform(-amount, amount) * 0.25) % 1.0
    s = min(max(s + rng.uniform(-amount, amount), 0.0), 1.0)
    v = min(max(v + rng.uniform(-amount, amount), 0.0), 1.0)
    r, g, b = colorsys.hsv_to_rgb(h, s, v)
    return (float(r), float(g), float(b))


def resolve_colors(spec: ModelSpec, color: Sequence[float] | None = None) -> dict[str, RGB]:
    """Role → RGB for one instance: the defaults, with ``color`` on the primary role."""
    colors = dict(spec.colors)
    if color is not None:
        colors[spec.primary] = (float(color[0]), float(color[1]), float(color[2]))
    return colors


FLOOR_COLORS = [(0.72, 0.62, 0.5), (0.55, 0.42, 0.3), (0.8, 0.78, 0.74), (0.45, 0.45, 0.47), (0.82, 0.7, 0.55), (0.6, 0.56, 0.5)]
WALL_COLORS = [(0.92, 0.91, 0.88), (0.86, 0.88, 0.9), (0.93, 0.88, 0.8), (0.8, 0.85, 0.8), (0.95, 0.95, 0.95), (0.85, 0.8, 0.78)]


def pick_color(rng: np.random.Generator, model: str) -> RGB | None:
    spec = get_model(model)
    if not spec.palette:
        return None
    base = spec.palette[int(rng.integers(len(spec.palette)))]
    c = jitter_color(base, rng, 0.08)
    return (round(c[0], 3), round(c[1], 3), round(c[2], 3))
