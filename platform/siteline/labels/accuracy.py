"""How accurate the masks of each change rule measured against a truth the renderer did not draw: the
synthetic scenes' analytic surfaces ray-cast per pixel (siteline.synth.viewtruth, ``bench/truth.py``,
24 views a pair, every other knob at the release default). A release quotes the row nearest its
rule, smallest region and density."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Measured:
    """One bench run: the scene, its density (points per m2), the rule and smallest region kept, and
    the changed class's precision, recall and F1 over every scored pixel, with the median number of
    false-change specks (components under 30 px) per view."""

    scene: str
    density: float
    rule: str
    min_region_points: int
    precision: float
    recall: float
    f1: float
    specks_median: float


# bench/truth.py, 2026-11-28, this 2-core machine (one run each; docs/performance.md)
MEASURED: tuple[Measured, ...] = (
    Measured("synthetic site", 10, "nearest", 1, 0.926, 0.979, 0.952, 330),
    Measured("synthetic site", 10, "surface", 8, 0.960, 0.974, 0.967, 28),
    Measured("synthetic site", 100, "nearest", 1, 0.943, 0.990, 0.966, 590),
    Measured("synthetic site", 100, "surface", 8, 0.971, 0.988, 0.979, 31),
    Measured("box scene", 40, "nearest", 1, 0.536, 0.986, 0.694, 696),
    Measured("box scene", 40, "surface", 8, 0.819, 0.985, 0.894, 4),
)


def density_of_spacing(spacing_m: float) -> float:
    """Points per m2 of a surface sampled at random whose median nearest-neighbour spacing is
    ``spacing_m`` (density x pi x spacing^2 = ln 2)."""
    return math.log(2) / (math.pi * spacing_m**2) if spacing_m > 0 else float("nan")


def measured_for(rule: str, min_region_points: int, spacing_m: float) -> Measured | None:
    """The measurement nearest (in log density) to a pair labelled by ``rule`` keeping regions of
    ``min_region_points`` at the median spacing ``spacing_m``; None when that rule was not measured."""
    rows = [m for m in MEASURED if m.rule == rule and m.min_region_points == min_region_points]
    density = density_of_spacing(spacing_m)
    if not rows or not math.isfinite(density):
        return None
    return min(rows, key=lambda m: (abs(math.log(m.density / density)), m.scene != "synthetic site"))


def accuracy_text(rule: str, min_region_points: int, spacing_m: float) -> str | None:
    """One sentence for a datasheet: what the rule measured nearest this pair's density."""
    m = measured_for(rule, min_region_points, spacing_m)
    if m is None:
        return None
    return (
        f"measured against analytic truth ({m.scene} at {m.density:g} points/m2, this rule and smallest region, "
        f"release defaults; this pair is at about {density_of_spacing(spacing_m):.0f} points/m2): changed-class "
        f"precision {m.precision:.2f}, recall {m.recall:.2f}, F1 {m.f1:.2f}, {m.specks_median:g} false specks "
        "(under 30 px) per view (median)"
    )
