"""Layout families beyond ``rooms``: places people live and work in, furnished with groups.

- ``corridor``: a corridor with doors at both ends and along it, offices off one or both sides;
- ``lshape``: an L-shaped flat (living room in one arm, kitchen/dining in the other, a bedroom);
- ``openplan``: one open space with kitchen, dining and living zones and a few partition stubs.

Every world validates (:func:`app.world.validation.validate_world`), holds every class at least once
and has a ``tour`` route planned on a grid inflated by the robot radius + margin (the same planner as
the rooms family). :func:`generate` (here and in :mod:`app.world.generator`, which adds ``rooms``)
is deterministic.

Example:
    >>> w = generate("corridor", 99000)
    >>> w.routes["tour"][:1]
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from shapely.geometry import Polygon

from app.world.furnish import T_IN, T_OUT, Builder
from app.world.types import Obstacle, Opening, Wall, World, WorldError

__all__ = ["FAMILIES", "generate_family"]


def _corridor(rng: np.random.Generator, seed: int) -> Any:
    L = round(float(rng.uniform(9.0, 13.0)), 1)
    cw = round(float(rng.uniform(1.6, 2.2)), 1)
    north = round(float(rng.uniform(3.0, 4.0)), 1)
    south = round(float(rng.uniform(2.8, 3.6)), 1) if rng.random() < 0.5 else 0.0
    y0, y1 = -south, cw + north
    b = Builder(rng, f"corridor_{seed}", seed,
                 f"corridor + offices (ocslam world random --family corridor --seed {seed}): {L} × {cw} m corridor")
    # corners CCW from (0, y0); edge 0: south, 1: east, 2: north, 3: west; corridor doors at both ends
    b.outer([(0.0, y0), (L, y0), (L, y1), (0.0, y1)], {1: [cw / 2 - y0], 3: [y1 - cw / 2]}, windows=3)
    n_off = int(rng.integers(2, 4))
    if n_off > 1:
        rng.uniform(0.3, 0.7, n_off - 1)  # an unused draw, kept so that every corridor world stays the same
    xs = [0.0] + [round(float((k + 1) * L / n_off + rng.uniform(-0.6, 0.6)), 1) for k in range(n_off - 1)] + [L]
    passages = []
    for k in range(n_off):
        a, c = xs[k], xs[k + 1]
        s = float(rng.uniform(a + 0.8, c - 0.8))
        passages.append(round(s, 2))
        b.zone(f"office N{k}", a + T_IN / 2 if k else T_OUT / 2, cw + T_IN / 2, c - T_IN / 2 if k < n_off - 1 else L - T_OUT / 2, y1 - T_OUT / 2)
    for k in range(1, n_off):
        b.inner((xs[k], cw), (xs[k], y1))
    # a closed door along the corridor's south wall (a closet or another flat), an office door or two
    s_doors = []
    s_pass = []
    if south > 0:
        m = int(rng.integers(1, 3))
        sx = [0.0] + [round(float((k + 1) * L / m + rng.uniform(-0.5, 0.5)), 1) for k in range(m - 1)] + [L]
        for k in range(m):
            s_pass.append(round(float(rng.uniform(sx[k] + 0.8, sx[k + 1] - 0.8)), 2))
            b.zone(f"office S{k}", sx[k] + T_IN / 2 if k else T_OUT / 2, y0 + T_OUT / 2, sx[k + 1] - T_IN / 2 if k < m - 1 else L - T_OUT / 2, -T_IN / 2)
        for k in range(1, m):
            b.inner((sx[k], y0), (sx[k], 0.0))
    else:
        for _ in range(int(rng.integers(1, 3))):
            s = round(float(rng.uniform(1.5, L - 1.5)), 2)
            if all(abs(s - t) > 1.6 for t in s_doors):
                s_doors.append(s)
    b.inner((0.0, cw), (L, cw), passages=passages, name="corridor north")
    if south > 0:
        b.inner((0.0, 0.0), (L, 0.0), passages=s_pass, name="corridor south")
    else:
        # the south outer wall is the corridor's; its doors are added as closed doors in an inner wall
        # lying on it would overlap, so they go into the outer wall: rebuild it with the doors
        w0 = b.world.walls[0]
        ops = tuple(sorted(list(w0.openings) + [Opening(s - 0.5 + T_OUT / 2, s + 0.5 + T_OUT / 2, 0.0, 2.1, "door") for s in s_doors],
                           key=lambda o: o.start))
        if all(o1.end <= o2.start for o1, o2 in zip(ops, ops[1:])):
            b.world.walls[0] = Wall(w0.start, w0.end, w0.thickness, w0.height, ops, name=w0.name)
            b._solid = None
            for s in s_doors:
                b._door(b.world.walls[0], s + T_OUT / 2)
    b.zone("corridor", T_OUT / 2, (T_OUT if south == 0 else T_IN) / 2, L - T_OUT / 2, cw - T_IN / 2)
    offices = [n for n, _ in b.zones if n.startswith("office")]
    plan = []
    for n in offices:
        plan.append((n, ["desk", "dining", "shelves", "lounge"][int(rng.integers(4))]))
        if rng.random() < 0.5:
            plan.append((n, ["shelves", "clutter", "desk"][int(rng.integers(3))]))
    plan += [("corridor", "clutter")]
    b.furnish(plan)
    b.person_by_door()
    if not b.complete_classes():
        return None
    order = ["corridor"] + offices + ["corridor"]
    return b.finish("corridor", order)


def _lshape(rng: np.random.Generator, seed: int) -> Any:
    W = round(float(rng.uniform(8.0, 11.0)), 1)
    H = round(float(rng.uniform(7.0, 9.0)), 1)
    w1 = round(float(rng.uniform(0.4, 0.55) * W), 1)  # the north arm's width
    h1 = round(float(rng.uniform(0.4, 0.55) * H), 1)  # the south arm's height
    b = Builder(rng, f"lshape_{seed}", seed, f"L-shaped flat (ocslam world random --family lshape --seed {seed}): {W} × {H} m")
    corners = [(0.0, 0.0), (W, 0.0), (W, h1), (w1, h1), (w1, H), (0.0, H)]
    doors = {int(rng.choice([0, 1])): [round(float(rng.uniform(1.0, (W if True else h1) - 1.0) if False else rng.uniform(0.8, 2.0)), 2)]}
    if rng.random() < 0.6:
        doors[4] = [round(float(rng.uniform(0.8, w1 - 0.8)), 2)]  # north edge (from (w1, H) to (0, H))
    b.outer(corners, doors, windows=4)
    # a bedroom in the north arm's end, behind a partition with a doorway (or a closed door)
    bed_y = round(float(rng.uniform(h1 + 2.4, H - 2.6)), 1) if H - h1 > 5.0 else None
    if bed_y is not None:
        s = round(float(rng.uniform(0.8, w1 - 0.8)), 2)
        b.inner((0.0, bed_y), (w1, bed_y), passages=[s], name="bedroom wall")
        b.zone("bedroom", T_OUT / 2, bed_y + T_IN / 2, w1 - T_OUT / 2, H - T_OUT / 2)
        b.zone("north arm", T_OUT / 2, h1 + 0.2, w1 - T_OUT / 2, bed_y - T_IN / 2)
    else:
        b.zone("north arm", T_OUT / 2, h1 + 0.2, w1 - T_OUT / 2, H - T_OUT / 2)
    b.zone("south arm", T_OUT / 2, T_OUT / 2, W - T_OUT / 2, h1 - T_OUT / 2)
    # the kitchen: a counter run against the east end
    if rng.random() < 0.8:
        cy = float(rng.uniform(1.3, max(1.31, h1 - 1.3)))
        g = b._footprint("kitchen_counter", W - T_OUT / 2 - 0.355, cy, math.pi)
        if g.within(Polygon([(0, 0), (W, 0), (W, h1), (0, h1)]).buffer(-0.1)) and not g.buffer(-0.01).intersects(b.solid) \
                and not any(g.intersects(k) for k in b.keepout):
            b.world.obstacles.append(Obstacle("model", round(W - T_OUT / 2 - 0.355, 3), round(cy, 3), math.pi, model="kitchen_counter"))
            b.placed.append(g)
    plan = [("south arm", "dining"), ("north arm", "lounge"), ("south arm", "shelves"), ("north arm", "clutter")]
    if bed_y is not None:
        plan += [("bedroom", "shelves"), ("bedroom", "desk")]
    b.furnish(plan)
    b.person_by_door()
    if not b.complete_classes():
        return None
    visit = ["south arm", "north arm"] + (["bedroom"] if bed_y is not None else []) + ["south arm"]
    return b.finish("south arm", visit)


def _openplan(rng: np.random.Generator, seed: int) -> Any:
    W = round(float(rng.uniform(8.0, 12.0)), 1)
    H = round(float(rng.uniform(6.0, 8.0)), 1)
    b = Builder(rng, f"openplan_{seed}", seed, f"open-plan flat (ocslam world random --family openplan --seed {seed}): {W} × {H} m")
    doors: dict[int, list[float]] = {int(rng.integers(4)): []}
    k = next(iter(doors))
    L = W if k in (0, 2) else H
    doors[k] = [round(float(rng.uniform(0.9, L - 0.9)), 2)]
    b.outer([(0.0, 0.0), (W, 0.0), (W, H), (0.0, H)], doors, windows=4)
    # one or two partition stubs from a wall split the space into zones without closing them
    stub_x = round(float(rng.uniform(0.4, 0.6) * W), 1)
    stub_len = round(float(rng.uniform(1.5, min(3.0, H - 3.0))), 1)
    if rng.random() < 0.5:
        b.inner((stub_x, H), (stub_x, H - stub_len), name="partition stub")
    else:
        b.inner((stub_x, 0.0), (stub_x, stub_len), name="partition stub")
    b.zone("west", T_OUT / 2, T_OUT / 2, stub_x - T_IN / 2, H - T_OUT / 2)
    b.zone("east", stub_x + T_IN / 2, T_OUT / 2, W - T_OUT / 2, H - T_OUT / 2)
    for model in ("kitchen_counter", "fridge", "tv_stand"):
        b.place([(None, model, 0.36 if model != "tv_stand" else 0.2, 0.0, 0.0)], dict(b.zones)["east" if model != "tv_stand" else "west"],
                wall=True, tries=20)
    plan = [("east", "dining"), ("west", "lounge"), ("west", "shelves"), ("east", "clutter"), ("west", "clutter")]
    if rng.random() < 0.5:
        plan.append(("east", "desk"))
    b.furnish(plan)
    b.person_by_door()
    if not b.complete_classes():
        return None
    return b.finish("east", ["east", "west", "east"])


#: family name → builder ``(rng, seed) → World | None``; ``rooms`` is :func:`app.world.rooms.rooms_world`'s own
FAMILIES: dict[str, Callable[[np.random.Generator, int], Any]] = {"corridor": _corridor, "lshape": _lshape, "openplan": _openplan}


def generate_family(family: str, seed: int, attempts: int = 30) -> World:
    """A valid world of one of :data:`FAMILIES` (``rooms`` and the entry point for all families:
    :func:`app.world.generator.generate`). Deterministic for ``(family, seed)``; ``WorldError`` if no
    attempt gave a valid world."""
    if family not in FAMILIES:
        raise WorldError(f"unknown layout family {family!r} (families: rooms, {', '.join(FAMILIES)})")
    rng = np.random.default_rng([seed, sorted(FAMILIES).index(family) + 1])
    for _ in range(attempts):
        w = FAMILIES[family](rng, seed)
        if w is not None:
            return w
    raise WorldError(f"world random --family {family} --seed {seed}: no valid world in {attempts} attempts")
