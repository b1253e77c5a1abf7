"""Physical class priors: every class, sane ranges, and the apartment's instances (spec §5) inside them."""

from __future__ import annotations

import pytest

from app.ocslam.classes import CLASS_PRIORS, ClassPrior, prior
from app.ocslam.messages import CLASS_NAMES

LIDAR_Z = 0.173

#: (class, footprint long side, short side, height) of the paper's apartment objects (spec §5).
APARTMENT = [
    ("ball", 0.225, 0.225, 0.235),
    ("dog", 0.95, 0.27, 0.7),
    ("gnome", 0.27, 0.21, 0.9),
    ("table", 1.8, 1.0, 0.74),
    ("chair", 1.1, 1.0, 0.8),  # armchair
    ("chair", 1.8, 1.0, 0.8),  # sofa
    ("door", 1.0, 0.05, 2.0),
    ("duck", 0.11, 0.07, 0.10),
    ("person", 0.45, 0.3, 1.8),
    ("extinguisher", 0.18, 0.18, 0.8),
    ("flowers", 0.17, 0.17, 0.95),
    ("shelf", 1.0, 0.4, 2.32),
]


def test_every_class_has_a_prior_in_order():
    assert tuple(CLASS_PRIORS) == CLASS_NAMES


@pytest.mark.parametrize("label,length,width,height", APARTMENT)
@pytest.mark.parametrize("scale", [0.8, 1.0, 1.2])
def test_apartment_objects_fit_their_prior_at_plus_minus_20_percent(label, length, width, height, scale):
    p = prior(label)
    assert p.length[0] <= length * scale <= p.length[2] or label == "door"  # doors come in fixed sizes
    assert p.width[0] <= width * scale <= p.width[2] * 1.2
    assert p.height[0] <= height * scale <= p.height[2]
    assert p.fits(length * scale, width * scale)


def test_only_the_duck_is_always_below_the_lidar_plane():
    below = [n for n, p in CLASS_PRIORS.items() if p.below_plane(LIDAR_Z)]
    assert below == ["duck"]
    maybe = {n for n, p in CLASS_PRIORS.items() if p.may_be_below_plane(LIDAR_Z)}
    assert {"duck", "ball"} <= maybe
    assert "door" not in maybe and "shelf" not in maybe


def test_legged_classes():
    assert {n for n, p in CLASS_PRIORS.items() if p.legged} == {"dog", "table", "person", "chair"}


def test_derived_extents_and_fit():
    t = prior("table")
    assert t.apparent_width_max == pytest.approx((2.3**2 + 1.35**2) ** 0.5)
    assert t.fits(1.8, 1.0) and t.fits(1.0, 1.8)
    assert not t.fits(3.0, 1.0) and not t.fits(1.8, 1.8)


def test_unknown_label_gets_a_permissive_prior_and_bad_priors_are_refused():
    p = prior("unicorn")
    assert p.fits(1.0, 1.0) and not p.legged
    with pytest.raises(ValueError):
        ClassPrior("bad", (1.0, 0.5, 2.0), (0.1, 0.2, 0.3), (0.1, 0.2, 0.3))
    with pytest.raises(ValueError):
        ClassPrior("bad", (0.1, 0.2, 0.3), (0.5, 0.6, 0.7), (0.1, 0.2, 0.3))
