"""Label parameters (DESIGN.md §4): the change radius, given or derived from the point spacing."""

from __future__ import annotations

import math
from dataclasses import dataclass

from siteline.errors import LabelError

LABEL_RULES = ("surface", "nearest")
# the surface rule's search radius, in change radii (SurfaceTest below)
SEARCH_MULTIPLIER = 2.0
# a probed point (found within the radius, but not near it) is changed only when it lies off the other
# scene's surface by at least this many change radii as well as its level of detection: a lone point of
# noise on an even surface then stays unchanged (bench trade at 10 points/m2: 2 specks a view without it, 1 with)
PROBE_OFFSET_MULTIPLIER = 0.25
# the least distance off a surface a point is judged changed at (range noise and registration error)
LOD_FLOOR_M = 0.05


@dataclass(frozen=True)
class SurfaceTest:
    """How the surface rule looks again at a point the nearest rule flags (module docstring):
    ``search_m`` the other scene's neighbourhood radius (metres), ``neighbours`` how many of its
    points to fit a plane to, the level of detection ``lod_sigmas`` x their RMS residual, at least
    ``lod_floor_m`` metres. ``probe_m``: a point whose nearest neighbour lies within the change radius
    but farther than this (metres) is probed against that surface too, and is changed when it lies
    off it by more than its level of detection and ``offset_m`` (inf: none is probed)."""

    search_m: float
    neighbours: int = 12
    lod_sigmas: float = 4.0
    lod_floor_m: float = LOD_FLOOR_M
    probe_m: float = math.inf
    offset_m: float = 0.0


@dataclass(frozen=True)
class LabelParams:
    """radius_m: change radius in metres, or None for ``radius_multiplier`` x the median
    nearest-neighbour spacing of the sparser scene. rule: ``surface`` (a point the nearest-neighbour
    test flags is looked at again against the other scene's local surface) or ``nearest`` (the
    nearest-neighbour test alone; siteline.labels.change). min_region_points: changed regions of
    fewer points are taken back to unchanged (siteline.labels.regions; 1 keeps every point).
    surface_probe: with the surface rule, a point whose nearest neighbour in the other scene lies
    within the change radius but farther than this many radii is probed against that scene's
    surface as well, and changed when it lies off it (a ramp deepened by less than the radius; 0:
    only the points the nearest test flags are looked at); not at a radius under the level of
    detection's floor, where it finds nothing."""

    radius_m: float | None = None
    radius_multiplier: float = 2.5
    rule: str = "surface"
    min_region_points: int = 1
    surface_probe: float = 0.0

    def surface_test(self, radius_m: float) -> SurfaceTest | None:
        """The surface rule's test at the change radius ``radius_m`` (None for the nearest rule)."""
        if self.rule != "surface":
            return None
        # a probed point's nearest neighbour lies within the radius: at a radius under the level of
        # detection's floor it hardly ever lies farther off the surface than that floor (none of 10M
        # points on a 30 m window at 8000 points/m2, r = 2.5 cm), so the probe is not run there
        if not self.surface_probe or radius_m <= LOD_FLOOR_M:
            return SurfaceTest(search_m=SEARCH_MULTIPLIER * radius_m)
        return SurfaceTest(
            search_m=SEARCH_MULTIPLIER * radius_m,
            probe_m=self.surface_probe * radius_m,
            offset_m=PROBE_OFFSET_MULTIPLIER * radius_m,
        )

    def __post_init__(self) -> None:
        if self.rule not in LABEL_RULES:
            raise LabelError(f"label rule {self.rule!r}: use one of {', '.join(LABEL_RULES)}.")
        if not (isinstance(self.min_region_points, int) and 1 <= self.min_region_points <= 100_000):
            raise LabelError(
                f"min_region_points {self.min_region_points!r} must be a whole number from 1 to 100000."
            )
        if self.radius_m is not None and not (
            isinstance(self.radius_m, int | float) and math.isfinite(self.radius_m) and self.radius_m > 0
        ):
            raise LabelError(f"radius {self.radius_m!r} m must be a positive number or 'auto'.")
        p = self.surface_probe
        if isinstance(p, bool) or not isinstance(p, int | float) or not 0 <= p < 1:
            raise LabelError(f"surface_probe {p!r} must be a number from 0 (off) to under 1 (change radii).")
        if not (isinstance(self.radius_multiplier, int | float) and self.radius_multiplier > 0):
            raise LabelError("radius multiplier must be positive.")


def expected_false_change(multiplier: float) -> dict[str, float | str]:
    """The expected share of an unchanged surface flagged changed at r = ``multiplier`` x the median
    nearest-neighbour spacing: 2^(-k^2) per direction (exact for randomly sampled surfaces, where
    density x pi x spacing^2 = ln 2; measured 49 / 20 / 5.6 / 1.0 / 0.09 % for k = 1, 1.5, 2, 2.5, 3
    on siteline's more regular synthetic scans, DESIGN.md §4), and about twice that in the symmetric
    2D mask (the union of both directions)."""
    per_direction = 2.0 ** (-(multiplier**2))
    return {
        "multiplier": float(multiplier),
        "per_direction": per_direction,
        "union": 1.0 - (1.0 - per_direction) ** 2,
        "rule": "2^(-k^2) per direction on unchanged surfaces (random sampling); union of both directions",
    }
