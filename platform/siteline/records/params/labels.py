"""Label parameters (DESIGN.md §4): the change radius, given or derived from the point spacing."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from siteline.errors import LabelError

LABEL_RULES = ("adaptive", "surface", "nearest")
# the rules that look again at a flagged point against the other scene's surface (SurfaceTest below)
SURFACE_RULES = ("adaptive", "surface")
# the surface rule's search radius, in change radii (SurfaceTest below)
SEARCH_MULTIPLIER = 2.0
# the adaptive rule (SurfaceTest): how far the points a plane is fitted to may lie, in change radii.
# On a scan flown as real flights are (siteline.synth.scanner), walls parallel to the lines are sampled
# at 1/25 of the roof's density and faces across them at 1/5 (the sloped scene at 80 points/m2): their
# spacing is up to 5x the ground's, so a plane needs 4x the surface rule's search to find them
REACH_MULTIPLIER = 8.0
# ... and the fewest points it is fitted to: 6 (three points fit any plane with no residual, so the
# level of detection stood at its floor and 1-2 % of a machine's and 6-8 % of a canopy's points were
# flagged on the sloped scene; with 6 none was)
MIN_FIT_POINTS = 6
# a point lies on the other scene's surface only within 1 in-plane RMS spread of its fitted points'
# middle (at a surface's edge the point lies about 0.7 of it off), and within 3 of their own spacings
# of the nearest (a random place on a surface sampled at random lies farther than 3 spacings from
# every point 0.2 % of the time: 2^-9); a plane that does not surround it says nothing of it
SURROUND_SPREADS, GAP_SPACINGS = 1.0, 3.0
# a probed point (found within the radius, but not near it) is changed only when it lies off the other
# scene's surface by at least this many change radii as well as its level of detection: a lone point of
# noise on an even surface then stays unchanged (bench trade at 10 points/m2: 2 specks a view without it, 1 with)
PROBE_OFFSET_MULTIPLIER = 0.25
# the least distance off a surface a point is judged changed at (range noise and registration error)
LOD_FLOOR_M = 0.05
# the adaptive rule probes only at a radius of two level-of-detection floors or more: below, a probed
# point can only be found off its surface between the floor and the radius, which two scans' range
# noise (2 cm each) reaches by chance (on the flown site at 1000 points/m2, r = 6.5 cm: 854 of 934
# false flags on a window of open ground came from the probe, 0 of its 1191 true ones)
ADAPTIVE_PROBE_MIN_RADIUS_M = 2 * LOD_FLOOR_M


@dataclass(frozen=True)
class SurfaceTest:
    """How the surface rule looks again at a point the nearest rule flags (siteline.labels.change):
    ``search_m`` the other scene's neighbourhood radius (metres; its plan cells too), ``neighbours``
    how many of its points to fit a plane to, the level of detection ``lod_sigmas`` x their RMS
    residual, at least ``lod_floor_m`` metres. ``probe_m``: a point whose nearest neighbour lies within
    the change radius but farther than this (metres) is probed against that surface too, and is changed
    when it lies off it by more than its level of detection and ``offset_m`` (inf: none is probed).

    The adaptive rule's test (None / 3 / inf / inf / False / False: the surface rule's): ``reach_m``, how far the
    ``neighbours`` nearest points may lie (metres; a wall the other scan grazed is sampled sparser than
    the ground the radius was taken from); ``min_fit``, the fewest of them a plane is fitted to (a plane
    through 3 points has no residual to take a level of detection from); ``surround``, how far the
    point may lie from their middle along the plane, in their in-plane RMS spread (beyond it the other
    surface ends before the point: a jib that turned, a slab that shrank); ``gap``, how far its nearest
    of them may lie, in their own spacing (farther, the point lies in a hole of that surface: a trench
    dug narrower than the reach); ``anchored``, where the plane fitted to them does not pass the point,
    whether some plane through it holds ``min_fit`` of them (a thinly sampled wall among the ground's
    points at its foot); ``observed``, a point with no
    surface of the other scene to judge it against is changed only when that scene holds nothing at or
    above it in its plan cell (open air it saw through), and is *not observed* otherwise (structure there
    may have hidden or grazed it), where that scene holds returns of the point's class beside it too few
    to fit (it grazed the point's surface: siteline.labels.change.grazed) or nothing in the cell at all."""

    search_m: float
    neighbours: int = 12
    lod_sigmas: float = 4.0
    lod_floor_m: float = LOD_FLOOR_M
    probe_m: float = math.inf
    offset_m: float = 0.0
    reach_m: float | None = None
    min_fit: int = 3
    surround: float = math.inf
    gap: float = math.inf
    anchored: bool = False
    observed: bool = False

    @property
    def fit_m(self) -> float:
        """How far the points a plane is fitted to may lie (metres)."""
        return self.search_m if self.reach_m is None else self.reach_m

    @property
    def halo_m(self) -> float:
        """How far from a point the other scene's points its flag depends on may lie (metres): the fit's
        reach, and its plan cell (the 8 around it too when ``observed``: two cells' width)."""
        return max(self.fit_m, (2.0 if self.observed else 1.0) * self.search_m)


@dataclass(frozen=True)
class LabelParams:
    """radius_m: change radius in metres, or None for ``radius_multiplier`` x the median
    nearest-neighbour spacing of the sparser scene. rule: ``adaptive`` (the default: a point the
    nearest-neighbour test flags is looked at again against the other scene's local surface as that
    scan sampled it, a place the other scan did not observe is ignored, and so is a point only that
    scan's returns of ignored classes hold: siteline.labels.change.held_by_any), ``surface`` (the same
    within twice the radius, where every surface is sampled alike) or ``nearest`` (the
    nearest-neighbour test alone; siteline.labels.change). min_region_points: changed regions of
    fewer points are taken back to unchanged (siteline.labels.regions; 1 keeps every point).
    surface_probe: with the surface rule, a point whose nearest neighbour in the other scene lies
    within the change radius but farther than this many radii is probed against that scene's
    surface as well, and changed when it lies off it (a ramp deepened by less than the radius; 0:
    only the points the nearest test flags are looked at); not at a radius under the level of
    detection's floor, where it finds nothing. sparse_regions: with ``min_region_points``, the changed
    samples of a surface sparser than the region cells, most of whose samples around changed, are
    kept whole (a pole's samples a metre apart; siteline.labels.store)."""

    radius_m: float | None = None
    radius_multiplier: float = 2.5
    rule: str = "adaptive"
    min_region_points: int = 1
    surface_probe: float = 0.0
    sparse_regions: bool = False

    def surface_test(self, radius_m: float) -> SurfaceTest | None:
        """The surface or adaptive rule's test at the change radius ``radius_m`` (None for the nearest rule)."""
        if self.rule not in SURFACE_RULES:
            return None
        test = SurfaceTest(search_m=SEARCH_MULTIPLIER * radius_m)
        if self.rule == "adaptive":
            test = replace(
                test, reach_m=REACH_MULTIPLIER * radius_m, min_fit=MIN_FIT_POINTS, surround=SURROUND_SPREADS,
                gap=GAP_SPACINGS, anchored=True, observed=True,
            )  # fmt: skip
        # a probed point's nearest neighbour lies within the radius: at a radius under the level of
        # detection's floor it hardly ever lies farther off the surface than that floor (none of 10M
        # points on a 30 m window at 8000 points/m2, r = 2.5 cm), so the probe is not run there (the
        # adaptive rule: not under two floors)
        floor = ADAPTIVE_PROBE_MIN_RADIUS_M if self.rule == "adaptive" else LOD_FLOOR_M
        if not self.surface_probe or radius_m <= floor:
            return test
        return replace(
            test, probe_m=self.surface_probe * radius_m, offset_m=PROBE_OFFSET_MULTIPLIER * radius_m
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
        if not isinstance(self.sparse_regions, bool):
            raise LabelError(f"sparse_regions {self.sparse_regions!r} must be true or false.")
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
