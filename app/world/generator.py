"""Random worlds: one entry point for every layout family, deterministic for ``(family, seed)``.

``rooms`` (the default, :mod:`app.world.rooms`) splits a rectangle into rooms; ``corridor``,
``lshape`` and ``openplan`` are :mod:`app.world.layouts`. Every world validates, holds every class
at least once and has a ``tour`` route.

Example:
    >>> w = random_world(seed=3)                                 # a valid randomized apartment
    >>> c = generate("corridor", 99000)                          # another layout family
"""

from __future__ import annotations

from app.world.layouts import FAMILIES, generate_family
from app.world.rooms import rooms_world
from app.world.types import World

__all__ = ["random_world", "generate", "FAMILIES"]


def random_world(seed: int, *, n_rooms: int | None = None, extra_objects: int | None = None, family: str = "rooms") -> World:
    """A randomized, valid world of a layout family, deterministic for ``(family, seed)``.

    ``rooms`` (the default): a randomized apartment, rooms with doorways, every class present,
    colours varied (:func:`app.world.rooms.rooms_world`, which takes ``n_rooms`` and ``extra_objects``).
    ``family`` other than ``rooms`` (``corridor``, ``lshape``, ``openplan``) builds that layout family
    instead (:mod:`app.world.layouts`).
    """
    if family != "rooms":
        return generate(family, seed)
    return rooms_world(seed, n_rooms=n_rooms, extra_objects=extra_objects)


def generate(family: str, seed: int, attempts: int = 30) -> World:
    """A valid world of a layout family (``rooms``, ``corridor``, ``lshape``, ``openplan``).
    Deterministic for ``(family, seed)``; ``WorldError`` if no attempt gave a valid world."""
    if family == "rooms":
        return rooms_world(seed)
    return generate_family(family, seed, attempts)
