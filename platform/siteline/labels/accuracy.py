"""How accurate the masks of each change rule measured against a truth the renderer did not draw: the
synthetic scenes' analytic surfaces ray-cast per pixel (siteline.synth.viewtruth, ``bench/trade.py``,
24 views a pair, every other knob at the release default). A release quotes the row of its rule,
smallest region and edge trim nearest its density."""

from __future__ import annotations

import math
from dataclasses import dataclass

from siteline.records.params.labels import SURFACE_RULES


@dataclass(frozen=True)
class Measured:
    """One bench run: the scene, its density (points per m2), the rule, smallest region kept,
    whether splats were trimmed at edges and the surface rule's probe (change radii; 0: none), and
    the changed class's precision, recall and F1 over every
    scored pixel, with the median number of isolated false-change specks (components under 30 px
    away from any true change) per view. Rows of flown scans (``scan``, siteline.synth.scanner) also
    give the largest share of an object that stayed labelled changed (``false_change``) and the share
    of the truth's pixels the masks ignore (``ignored``); NaN where not measured. ``unsure_edges``:
    the masks ignored a farther surface drawn where a nearer one of other change may lie (the pair
    knob of that name, with the trim); ``sparse_surfaces``: a sparse surface's changes kept whole and
    what shows between its samples ignored too (the pair knob of that name)."""

    scene: str
    density: float
    rule: str
    min_region_points: int
    trim_edges: bool
    precision: float
    recall: float
    f1: float
    specks_median: float
    surface_probe: float = 0.0
    scan: str = "sampled"
    false_change: float = math.nan
    ignored: float = math.nan
    unsure_edges: bool = False
    sparse_surfaces: bool = False


# `siteline bench trade`, one run each (docs/performance.md): the nearest rule as releases made it
# before, the surface rule without the probe (2026-11-28, the defaults until the probe), the surface
# rule with the probe at 0.7 (2026-11-28 later; the runs without it repeated the rows above), all on
# sampled epochs
MEASURED: tuple[Measured, ...] = (
    Measured("synthetic site", 10, "nearest", 1, False, 0.928, 0.978, 0.952, 246),
    Measured("synthetic site", 10, "surface", 8, True, 0.977, 0.963, 0.970, 1),
    Measured("synthetic site", 10, "surface", 8, True, 0.977, 0.969, 0.973, 1, 0.7),
    Measured("synthetic site", 100, "nearest", 1, False, 0.942, 0.990, 0.966, 524),
    Measured("synthetic site", 100, "surface", 8, True, 0.984, 0.983, 0.983, 0),
    Measured("synthetic site", 100, "surface", 8, True, 0.983, 0.986, 0.985, 0, 0.7),
    Measured("synthetic site", 1000, "nearest", 1, False, 0.901, 0.994, 0.945, 2051),
    Measured("synthetic site", 1000, "surface", 8, True, 0.985, 0.990, 0.988, 0),
    Measured("synthetic site", 1000, "surface", 8, True, 0.985, 0.990, 0.988, 0, 0.7),
    Measured("box scene", 40, "nearest", 1, False, 0.536, 0.986, 0.694, 693),
    Measured("box scene", 40, "surface", 8, True, 0.953, 0.956, 0.955, 0),
    Measured("box scene", 40, "surface", 8, True, 0.953, 0.960, 0.956, 0, 0.7),
    # the adaptive rule, the default since 2026-11-29, on epochs flown as real flights are (issue 68):
    # the largest false change on an object that stayed (seen on 100 pixels or more), the share of the
    # truth's pixels the masks ignore
    Measured("synthetic site", 10, "adaptive", 3, True, 0.989, 0.953, 0.971, 0, 0.7, "flown", 0.012, 0.043),
    Measured("box scene", 40, "adaptive", 3, True, 0.974, 0.799, 0.878, 0, 0.7, "flown", 0.003, 0.007),
    Measured("sloped scene", 80, "adaptive", 3, True, 0.977, 0.970, 0.973, 0, 0.7, "flown", 0.001, 0.023),
    Measured("synthetic site", 1000, "adaptive", 3, True, 0.992, 0.973, 0.982, 2, 0.7, "flown", 0.010, 0.025),
    # unsure edges ignored (the default since issue 67's fourth item, 2026-11-29), views chosen around
    # the changes (sampler keyed-sha256-3): 24 views a pair on the site (its photos' cameras), 48 on the
    # others (LiDAR only: cameras planned from the scan)
    Measured(
        "synthetic site", 10, "adaptive", 3, True, 0.988, 0.947, 0.967, 4, 0.7, "flown", 0.018, 0.045, True
    ),
    Measured("box scene", 40, "adaptive", 3, True, 0.958, 0.893, 0.925, 0, 0.7, "flown", 0.003, 0.012, True),
    Measured(
        "sloped scene", 80, "adaptive", 3, True, 0.959, 0.935, 0.947, 0, 0.7, "flown", 0.013, 0.013, True
    ),
    Measured(
        "synthetic site", 1000, "adaptive", 3, True, 0.992, 0.965, 0.979, 9, 0.7, "flown", 0.019, 0.049, True
    ),
    # sparse surfaces kept in the labels and said unsure behind (the default since 2026-11-29, issues
    # 67-68): the same scenes and views; the two sites and the box scene re-measured with the adaptive
    # rule's third version (a fence on the fence line, a fence both scans saw edge-on: not observed;
    # the box scene's views, chosen around its changes, moved with 11 of its jib's points), the masks
    # unsure behind sparse surfaces that stayed too (the box scene's mast), and specks counted away
    # from every truly changed pixel
    Measured(
        "synthetic site",
        10,
        "adaptive",
        3,
        True,
        0.988,
        0.955,
        0.972,
        0,
        0.7,
        "flown",
        0.006,
        0.059,
        True,
        True,
    ),
    Measured(
        "box scene", 40, "adaptive", 3, True, 0.954, 0.906, 0.930, 0, 0.7, "flown", 0.006, 0.012, True, True
    ),
    Measured(
        "sloped scene",
        80,
        "adaptive",
        3,
        True,
        0.959,
        0.944,
        0.952,
        0,
        0.7,
        "flown",
        0.013,
        0.014,
        True,
        True,
    ),
    Measured(
        "synthetic site",
        1000,
        "adaptive",
        3,
        True,
        0.993,
        0.989,
        0.991,
        1,
        0.7,
        "flown",
        0.003,
        0.044,
        True,
        True,
    ),
)


def density_of_spacing(spacing_m: float) -> float:
    """Points per m2 of a surface sampled at random whose median nearest-neighbour spacing is
    ``spacing_m`` (density x pi x spacing^2 = ln 2)."""
    return math.log(2) / (math.pi * spacing_m**2) if spacing_m > 0 else float("nan")


def measured_for(
    rule: str,
    min_region_points: int,
    trim_edges: bool,
    spacing_m: float,
    surface_probe: float = 0.0,
    unsure_edges: bool = False,
    sparse_surfaces: bool = False,
) -> Measured | None:
    """The measurement nearest (in log density) to a pair labelled by ``rule`` keeping regions of
    ``min_region_points``, its splats trimmed at edges or not, with the surface rule's
    ``surface_probe``, unsure edges ignored or not (only with the trim) and sparse surfaces kept or
    not (only with unsure edges), at the median spacing ``spacing_m``; None when those settings were
    not measured."""
    probe = surface_probe if rule in SURFACE_RULES else 0.0
    unsure = unsure_edges and trim_edges
    key = (rule, min_region_points, trim_edges, probe, unsure, sparse_surfaces and unsure)
    rows = [
        m
        for m in MEASURED
        if (m.rule, m.min_region_points, m.trim_edges, m.surface_probe, m.unsure_edges, m.sparse_surfaces)
        == key
    ]
    density = density_of_spacing(spacing_m)
    if not rows or not math.isfinite(density):
        return None
    return min(rows, key=lambda m: (abs(math.log(m.density / density)), m.scene != "synthetic site"))


def accuracy_text(
    rule: str,
    min_region_points: int,
    trim_edges: bool,
    spacing_m: float,
    surface_probe: float = 0.0,
    unsure_edges: bool = False,
    sparse_surfaces: bool = False,
) -> str | None:
    """One sentence for a datasheet: what the settings measured nearest this pair's density (with
    unsure edges ignored and sparse surfaces kept where those settings were measured so, else the
    nearest settings measured without them, saying so)."""
    m = measured_for(
        rule, min_region_points, trim_edges, spacing_m, surface_probe, unsure_edges, sparse_surfaces
    )
    m = m or measured_for(rule, min_region_points, trim_edges, spacing_m, surface_probe, unsure_edges)
    m = m or measured_for(rule, min_region_points, trim_edges, spacing_m, surface_probe)
    if m is None:
        return None
    unsure = unsure_edges and trim_edges
    before = (
        "; measured before unsure edges were ignored"
        if unsure and not m.unsure_edges
        else "; measured before sparse surfaces were kept"
        if unsure and sparse_surfaces and not m.sparse_surfaces
        else ""
    )
    flown = (
        f"; on the objects that stayed at most {m.false_change:.1%} of pixels called changed, "
        f"{m.ignored:.1%} of the truth's pixels ignored"
        if math.isfinite(m.false_change) and math.isfinite(m.ignored)
        else ""
    )
    return (
        f"measured against analytic truth ({m.scene} at {m.density:g} points/m2, {m.scan} epochs, this rule, "
        f"smallest region, edge trim{', unsure edges' if m.unsure_edges else ''}"
        f"{', sparse surfaces' if m.sparse_surfaces else ''} and probe, "
        f"release defaults; this pair is at about {density_of_spacing(spacing_m):.0f} points/m2): changed-class "
        f"precision {m.precision:.2f}, recall {m.recall:.2f}, F1 {m.f1:.2f}, {m.specks_median:g} isolated false "
        "specks (under 30 px) per view (median)" + flown + before
    )
