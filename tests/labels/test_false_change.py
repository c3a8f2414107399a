"""The change radius's false-change rate on an unchanged surface matches what releases record."""

from __future__ import annotations

import numpy as np
import pytest

from siteline.labels.change import CHANGED, change_flags, median_spacing
from siteline.records.params.labels import expected_false_change
from siteline.records.params.pairs import PairParams
from siteline.site.taxonomy import default_taxonomy


def _surface(rng: np.random.Generator, n: int, side_m: float) -> np.ndarray:
    """An unchanged open surface sampled at random: (n, 3) site-local metres on a gentle slope."""
    xy = rng.uniform(0.0, side_m, (n, 2))
    return np.c_[xy, 0.02 * xy[:, 0]]


@pytest.mark.parametrize("multiplier", [PairParams().radius_multiplier, 2.0])
def test_false_change_at_the_default_multiplier_is_within_the_recorded_expectation(multiplier: float) -> None:
    rng = np.random.default_rng(7)
    side = 40.0
    a, b = _surface(rng, 80_000, side), _surface(rng, 80_000, side)  # two scans of the same ground
    spacing = max(median_spacing(a), median_spacing(b))
    radius = multiplier * spacing
    ground = np.full(len(a), default_taxonomy().id_of("ground"), np.uint8)
    flags = change_flags(a, ground, b, ground, radius, default_taxonomy().ignored_lut())
    interior = np.all(
        (a[:, :2] > 1.0) & (a[:, :2] < side - 1.0), axis=1
    )  # the border has no neighbours beyond
    measured = float((flags[interior] == CHANGED).mean())
    expected = expected_false_change(multiplier)["per_direction"]
    assert expected / 1.5 < measured < expected * 1.5, (measured, expected)
