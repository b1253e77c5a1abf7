"""Physical priors of the detector's 11 classes: footprint, height, legs, LIDAR cross-section.

The Consciousness node uses them to tell a right island from a wrong one (the *corner problem*),
to group the legs of one object, to complete the footprint of an object seen from one side, and to
place objects the LIDAR cannot see (below its plane) from the camera alone.

Sizes come from the paper's apartment (spec §5) and are widened for the random worlds, which
scale objects by up to ±20 % and vary the models. Each size is ``(min, nominal, max)`` in metres:

- ``length``: the longer horizontal side of the object's footprint,
- ``width``: the shorter horizontal side,
- ``height``: the top above the floor.

``shapes``: typical ``(long, short)`` footprints of real instances (a chair may be a dining chair, an
armchair or a sofa); a visible face matched against them gives the unseen depth.
``legged``: the LIDAR plane may cut the object in several separate legs (table, dog, person, dining
chair); ``leg_span``: the largest ``(long, short)`` extent of the legs of one instance.
``solid_fraction``: the central fraction of the box's width in which the object blocks the LIDAR
beams (a door blocks all of it, a potted plant only its pot): used by the see-through check.
``on_wall``: the object sits in a wall (doors), so its island legitimately continues into the wall.
``pedestal``: some instances stand on one central support much smaller than the object (a round table's
column), so a lone small island on the box's centre line may be all the LIDAR ever sees of it.
``open_span``: the floor the LIDAR may see free inside one instance (an open bookcase's frame, a door's jambs), beyond
the span of a legged class's legs; any wider stretch seen free between two point sets parts them into two objects.
``top_at_front``: the object's highest point stands above its nearest face (a bookcase's front top edge): a box's
top row shows it at the range of the object's front, not farther back (a chair's back, a person's head).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.ocslam.messages import CLASS_NAMES


@dataclass(frozen=True, slots=True)
class ClassPrior:
    """Physical size and LIDAR appearance of one class (metres)."""

    name: str
    length: tuple[float, float, float]
    width: tuple[float, float, float]
    height: tuple[float, float, float]
    legged: bool = False
    solid_fraction: float = 0.0
    on_wall: bool = False
    pedestal: bool = False
    top_at_front: bool = False
    #: Largest horizontal extent of one leg island (m); islands larger than this are never legs.
    leg_size_max: float = 0.35
    shapes: tuple[tuple[float, float], ...] = ()
    leg_span: tuple[float, float] | None = None
    #: typical ``(long, short)`` footprints of the legs alone (legs at the corners: the same as ``shapes``)
    leg_shapes: tuple[tuple[float, float], ...] = ()
    #: largest island one instance can give at LIDAR height (m, bounding-box diagonal; inf: no limit).
    #: Classes that are legs at that height (tables, dogs, people) never give a wall-sized island.
    max_island: float = float("inf")
    #: largest stretch of floor the LIDAR may see free inside one instance (m): between a bookcase's side panels,
    #: a door's jambs; ``None``: the legs' largest span for a legged class, else 0 (a solid cross-section)
    open_span: float | None = None

    def __post_init__(self) -> None:
        for key in ("length", "width", "height"):
            lo, nom, hi = getattr(self, key)
            if not (0.0 < lo <= nom <= hi):
                raise ValueError(f"class prior {self.name}.{key}: need 0 < min <= nominal <= max, got {(lo, nom, hi)}")
        if self.width[2] > self.length[2] or self.width[1] > self.length[1]:
            raise ValueError(f"class prior {self.name}: width is the shorter side")
        if not self.shapes:
            object.__setattr__(self, "shapes", ((self.length[1], self.width[1]),))
        if self.legged and self.leg_span is None:
            object.__setattr__(self, "leg_span", (self.length[2], self.width[2]))
        if self.legged and not self.leg_shapes:
            object.__setattr__(self, "leg_shapes", self.shapes)

    @property
    def free_span(self) -> float:
        """Largest stretch of floor seen free inside one instance (m): ``open_span``, else the legs' largest span
        for a legged class, else 0."""
        if self.open_span is not None:
            return float(self.open_span)
        return float(self.leg_span[0]) if self.legged and self.leg_span is not None else 0.0

    def fits_typical(self, extent_a: float, extent_b: float, tolerance: float = 0.2) -> bool:
        """True if a footprint with these extents fits inside one of the typical shapes (scaled by 1 + tol)."""
        big, small = max(extent_a, extent_b), min(extent_a, extent_b)
        return any(big <= a * (1.0 + tolerance) + 0.1 and small <= b * (1.0 + tolerance) + 0.1 for a, b in self.shapes)

    def legs_fit(self, extent_a: float, extent_b: float, tolerance: float = 0.3) -> bool:
        """True if a group of leg islands with these extents fits the legs of one typical instance
        (one of ``leg_shapes`` scaled by 1 + ``tolerance``, never beyond ``leg_span``)."""
        if self.leg_span is None:
            return False
        big, small = max(extent_a, extent_b), min(extent_a, extent_b)
        if big > self.leg_span[0] or small > self.leg_span[1]:
            return False
        return any(big <= a * (1.0 + tolerance) + 0.05 and small <= b * (1.0 + tolerance) + 0.05 for a, b in self.leg_shapes)

    # -- derived extents ---------------------------------------------------------------------------
    @property
    def apparent_width_min(self) -> float:
        """Smallest horizontal extent the object can show to the camera (its thinnest side)."""
        return self.width[0]

    @property
    def apparent_width_max(self) -> float:
        """Largest horizontal extent it can show (the diagonal of the largest footprint)."""
        return float(np.hypot(self.length[2], self.width[2]))

    @property
    def diagonal_nominal(self) -> float:
        return float(np.hypot(self.length[1], self.width[1]))

    def below_plane(self, z: float) -> bool:
        """True if even the tallest instance stays below height ``z`` (the LIDAR never sees it)."""
        return self.height[2] < z

    def may_be_below_plane(self, z: float, margin: float = 0.03) -> bool:
        """True if a small instance may pass under the plane at ``z`` or only graze it."""
        return self.height[0] < z + margin

    def fits(self, extent_a: float, extent_b: float, tolerance: float = 0.15) -> bool:
        """True if a footprint with these two extents fits inside the largest instance."""
        big, small = max(extent_a, extent_b), min(extent_a, extent_b)
        return big <= self.length[2] * (1.0 + tolerance) and small <= self.width[2] * (1.0 + tolerance) + 0.05


#: Priors in ``CLASS_NAMES`` order. Nominal values: the apartment's instances (spec §5); typical
#: shapes: common real instances of the class (dining table / round table; dining chair / armchair /
#: two- and three-seat sofa; tall / low bookcase).
CLASS_PRIORS: dict[str, ClassPrior] = {
    p.name: p
    for p in (
        ClassPrior("ball", (0.14, 0.225, 0.32), (0.14, 0.225, 0.32), (0.14, 0.225, 0.34), solid_fraction=0.5),
        ClassPrior(
            "dog", (0.45, 1.0, 1.4), (0.15, 0.27, 0.55), (0.35, 0.74, 1.0),
            legged=True, leg_size_max=0.35, leg_span=(0.8, 0.45), leg_shapes=((0.54, 0.27),), max_island=0.5,
        ),
        ClassPrior("gnome", (0.14, 0.3, 0.45), (0.12, 0.25, 0.4), (0.3, 0.94, 1.2), solid_fraction=0.3),
        ClassPrior(
            "table", (0.7, 1.8, 2.3), (0.45, 1.0, 1.35), (0.45, 0.74, 1.0),
            legged=True, leg_size_max=0.25, shapes=((1.8, 1.0), (1.0, 1.0)), leg_span=(2.3, 1.35), max_island=0.45,
            pedestal=True,
        ),
        ClassPrior(
            "chair", (0.35, 1.1, 2.7), (0.3, 1.0, 1.3), (0.45, 0.8, 1.3), solid_fraction=0.4,
            legged=True, leg_size_max=0.15, shapes=((1.1, 1.0), (0.44, 0.44), (1.8, 1.0), (2.2, 1.0)), leg_span=(0.6, 0.6),
            leg_shapes=((0.42, 0.42),),
        ),
        ClassPrior(
            "door", (0.6, 1.0, 1.3), (0.02, 0.3, 0.45), (1.6, 2.1, 2.6), solid_fraction=0.6, on_wall=True,
            top_at_front=True, shapes=((1.0, 0.3),), open_span=1.3,
        ),
        ClassPrior("duck", (0.05, 0.11, 0.2), (0.04, 0.075, 0.16), (0.05, 0.1, 0.16)),
        ClassPrior(
            "person", (0.25, 0.6, 0.85), (0.15, 0.3, 0.55), (1.2, 1.8, 2.3),
            legged=True, leg_size_max=0.2, leg_span=(0.6, 0.4), leg_shapes=((0.37, 0.14),), max_island=0.55,
        ),
        ClassPrior("extinguisher", (0.1, 0.23, 0.4), (0.08, 0.18, 0.35), (0.3, 0.77, 1.0), solid_fraction=0.3),
        ClassPrior("flowers", (0.12, 0.25, 0.7), (0.12, 0.19, 0.7), (0.35, 0.99, 1.4), solid_fraction=0.1),
        ClassPrior(
            "shelf", (0.6, 1.0, 1.5), (0.25, 0.4, 0.7), (0.9, 2.3, 2.9), solid_fraction=0.5, top_at_front=True,
            shapes=((1.0, 0.4), (1.2, 0.35)), open_span=1.5,
        ),
    )
}

assert tuple(CLASS_PRIORS) == CLASS_NAMES, "class priors must follow CLASS_NAMES"


def prior(label: str) -> ClassPrior:
    """The prior of ``label``; an unknown label gets a permissive generic prior (never raises)."""
    p = CLASS_PRIORS.get(label)
    if p is not None:
        return p
    return ClassPrior(label, (0.05, 0.5, 3.0), (0.05, 0.4, 3.0), (0.05, 1.0, 3.0))
