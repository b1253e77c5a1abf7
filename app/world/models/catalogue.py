"""The object model catalogue: every model a world file may name (:data:`MODELS`).

The models are built from coloured parts (:mod:`app.world.models.parts`) by kind:
:mod:`~app.world.models.objects` (small classified objects and clutter),
:mod:`~app.world.models.furniture` and :mod:`~app.world.models.fixtures`. The same parts build the
pybullet bodies (:mod:`~app.world.models.bodies`), the footprints and height ranges
(:mod:`~app.world.models.geometry`) and the trimesh visuals (:mod:`~app.world.models.meshes`).
Real meshes come from ``pybullet_data`` where one fits (rubber duck, soccer ball, wooden table top);
the rest is primitives and the unit meshes written by ``scripts/make_object_meshes.py``
(``assets/meshes/objects``).

Example:
    >>> spec = get_model("dog")
    >>> spec.label, spec.legged
    ('dog', True)
"""

from __future__ import annotations

from app.ocslam.messages import CLASS_NAMES
from app.world.models.fixtures import beacon_model, door_model, painting_model
from app.world.models.furniture import (
    bookshelf_model,
    dining_chair_model,
    fridge_model,
    kitchen_counter_model,
    low_shelf_model,
    round_table_model,
    sofa_model,
    stool_model,
    table_model,
    tv_stand_model,
)
from app.world.models.objects import (
    cardboard_box_model,
    dog_model,
    extinguisher_model,
    flowers_model,
    gnome_model,
    person_model,
    play_ball_model,
    rubber_duck_model,
    soccer_ball_model,
    trash_bin_model,
)
from app.world.models.parts import ModelSpec

__all__ = ["MODELS", "get_model", "models_for_class", "class_models"]


def _build_catalogue() -> dict[str, ModelSpec]:
    specs = [
        soccer_ball_model(),
        play_ball_model(),
        dog_model(),
        gnome_model(),
        table_model(),
        round_table_model(),
        dining_chair_model(),
        sofa_model("armchair", 1.1, 1, "armchair 1.0 deep × 1.1 wide × 0.8 m on 0.1 m feet, seat toward +x"),
        sofa_model("sofa", 1.8, 2, "two-seat sofa 1.0 deep × 1.8 wide × 0.8 m on 0.1 m feet, seat toward +x"),
        sofa_model("sofa3", 2.2, 3, "three-seat sofa 1.0 deep × 2.2 wide × 0.8 m on 0.1 m feet, seat toward +x"),
        door_model(),
        rubber_duck_model(),
        person_model(),
        extinguisher_model(),
        flowers_model(),
        bookshelf_model(),
        low_shelf_model(),
        fridge_model(),
        kitchen_counter_model(),
        stool_model(),
        trash_bin_model(),
        cardboard_box_model(),
        tv_stand_model(),
        painting_model(),
        beacon_model(),
    ]
    return {s.name: s for s in specs}


#: name → spec, for every model a world file may use.
MODELS: dict[str, ModelSpec] = _build_catalogue()


def get_model(name: str) -> ModelSpec:
    """The catalogue entry; ``KeyError`` with the list of known models."""
    try:
        return MODELS[name]
    except KeyError:
        raise KeyError(f"unknown model {name!r} (known: {', '.join(sorted(MODELS))})") from None


def models_for_class(label: str | None) -> list[str]:
    """Model names whose class is ``label`` (``None``: the unclassified models)."""
    return [n for n, s in MODELS.items() if s.label == label]


def class_models() -> dict[str, list[str]]:
    """Class name → its model names, for every class of :data:`CLASS_NAMES`."""
    return {c: models_for_class(c) for c in CLASS_NAMES}
