"""Synthetic view parameters (DESIGN.md §5 defaults), persisted with every view set."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass

from siteline.errors import RenderError, ViewsError
from siteline.records.enums import MIRROR_RULES
from siteline.records.params.render import WORLD_SPLAT_FACTOR, RenderParams
from siteline.records.specs import parse_spec
from siteline.schema import JSON

# Recorded with every view set (lineage): how the sample was drawn.
# 2: cameras clear both scenes' full-density points by clearance_m (3 m; before: 1 m of the later
# scene's coarse copy), so the same parameters draw other views
# 3: each changed region of a pair is in change_views views where candidates show it, in place of
# the last views of the stratified sample (siteline.views.generate.cover_changes)
SAMPLER_VERSION = "keyed-sha256-3"


@dataclass(frozen=True)
class ViewParams:
    """vertical_fractions: camera heights kept, as fractions of the real camera's height above the
    ground plane (moved along the plane normal, orientation kept).
    mirror: add a mirror of each view across the nearest fence segment; mirror_rule: how a mirrored
    camera is oriented (``aim-site``: at the real camera's ground target, or the site's centre;
    ``reflect``: the reflected direction; siteline.views.strategies.mirror).
    forward_fractions: steps along the optical axis, as fractions of the median depth of the central
    image region (``central_fraction`` of the width and height).
    depth_probe_scale: render scale of the depth probe that measures that median (of the real image).
    clearance_m: reject views whose centre is within this distance (metres) of a point of either scene
    of the pair, at full density (3 m: a camera nearer draws a surface from points tens of pixels
    apart, and a drone would not fly there).
    min_height_m: reject views lower than this above the ground plane (underground).
    overhead_radius_m: reject views with points above them within this horizontal radius (under a
    slab, inside a building).
    scale, min_coverage: reject views whose coverage at render scale ``scale`` is below min_coverage.
    min_valid: reject views whose probe shows less than this share of pixels of kept points (a class
    that is not ignored, inside the fence): the pair's valid share can only be lower.
    point_size_px, splat, splat_max_px, splat_factor: the renders' splats, which the coverage probes draw.
    max_spacing_px: with world splats, reject views that draw more than a tenth of their surface from
    points farther apart than this many pixels at ``scale`` (siteline.views.generate.sparse_share:
    a close-up of a sparse roof is a mosaic of disks); 0: no such test. 15 by default, about the
    largest spacing the default splats close (31 px at most, 2 x the spacing); 8 keeps sharper
    views at the cost of farther ones (docs/performance.md measures both).
    probe_factor: with world splats, coverage probes render at this fraction of ``scale`` (a
    sixteenth of the pixels at 0.25), with point sizes scaled alike (at least 1 px): a probe then
    costs about a sixteenth of a render, and since each splat spans its spacing whatever the pixel
    size, its coverage and valid share stay within a few points of the render's. Fixed splats are
    probed at the view scale (their coverage depends on the pixel size).
    change_views, change_min_px, change_min_m2: with a pair's changed regions known
    (siteline.pairs.regions), each region of at least ``change_min_m2`` square metres is shown by at
    least ``change_views`` views at ``change_min_px`` pixels or more at ``scale`` where candidates
    that show it exist: views are added for it in place of the last views of the stratified sample
    that no other region needs (siteline.views.generate.cover_changes); 0 views: no such planning.
    change_share: at most this share of the views is chosen so (the rest stays the paper's stratified
    sample): on the demo's 24 views, 44 regions took most of them, and the pair's F1 fell 0.978 ->
    0.967 with 0 -> 4 specks a view (docs/performance.md).
    views: views kept per pair (seeded sample, stratified by strategy). ``scale`` and ``views`` are the
    knobs of the same names in PairParams and RenderParams.
    """

    vertical_fractions: tuple[float, ...] = (1.0, 0.75, 0.5, 0.25)
    mirror: bool = True
    mirror_rule: str = "aim-site"
    forward_fractions: tuple[float, ...] = (0.0, 0.25, 0.5, 0.75)
    central_fraction: float = 0.5
    depth_probe_scale: float = 0.0625
    clearance_m: float = 3.0
    min_height_m: float = 1.0
    overhead_radius_m: float = 1.0
    scale: float = 0.125
    min_coverage: float = 0.5
    views: int = 300
    seed: int = 0
    point_size_px: int = 1
    min_valid: float = 0.0
    splat: str = "fixed"
    splat_max_px: int = 31
    probe_factor: float = 0.25
    splat_factor: float = WORLD_SPLAT_FACTOR
    max_spacing_px: float = 15.0
    change_views: int = 5
    change_min_px: int = 50
    change_min_m2: float = 1.0
    change_share: float = 0.25

    def __post_init__(self) -> None:
        for name in ("vertical_fractions", "forward_fractions"):
            vals = getattr(self, name)
            if not vals or not all(isinstance(v, int | float) and math.isfinite(v) for v in vals):
                raise ViewsError(f"{name} must be a non-empty list of numbers, got {vals!r}.")
        if not all(0 < v <= 1 for v in self.vertical_fractions):
            raise ViewsError(f"vertical_fractions must lie in (0, 1], got {self.vertical_fractions}.")
        if not all(0 <= v < 1 for v in self.forward_fractions):
            raise ViewsError(f"forward_fractions must lie in [0, 1), got {self.forward_fractions}.")
        if self.mirror_rule not in MIRROR_RULES:
            raise ViewsError(f"mirror_rule {self.mirror_rule!r}: use one of {MIRROR_RULES}.")
        if not 0 < self.central_fraction <= 1:
            raise ViewsError(f"central_fraction {self.central_fraction} must lie in (0, 1].")
        if not 0 <= self.min_coverage <= 1:
            raise ViewsError(f"min_coverage {self.min_coverage} must lie in [0, 1].")
        if not 0 <= self.min_valid <= 1:
            raise ViewsError(f"min_valid {self.min_valid} must lie in [0, 1].")
        if not isinstance(self.views, int) or self.views < 1:
            raise ViewsError(f"views must be at least 1, got {self.views}.")
        if not 0 < self.probe_factor <= 1:
            raise ViewsError(f"probe_factor {self.probe_factor} must lie in (0, 1].")
        if not self.max_spacing_px >= 0:
            raise ViewsError(
                f"max_spacing_px {self.max_spacing_px} must be a number of pixels (0: no such test)."
            )
        if not isinstance(self.change_views, int) or self.change_views < 0:
            raise ViewsError(f"change_views must be a number of views (0: none), got {self.change_views!r}.")
        if not isinstance(self.change_min_px, int) or self.change_min_px < 1:
            raise ViewsError(f"change_min_px must be at least 1 pixel, got {self.change_min_px!r}.")
        if not 0 <= self.change_share <= 1:
            raise ViewsError(f"change_share must lie in [0, 1], got {self.change_share!r}.")
        if not self.change_min_m2 >= 0:
            raise ViewsError(
                f"change_min_m2 must be square metres (0: every region), got {self.change_min_m2!r}."
            )
        for name in ("clearance_m", "overhead_radius_m", "scale", "depth_probe_scale"):
            if not getattr(self, name) > 0:
                raise ViewsError(f"{name} must be positive.")
        try:  # the renderer's rule for point sizes, one place
            self.probe_settings()
        except RenderError as exc:
            raise ViewsError(str(exc)) from exc

    def probe_settings(self, scale: float | None = None) -> RenderParams:
        """The render settings of a probe at ``scale`` (the coverage probe's, ``probe_factor`` x the
        view scale, when None): the renders' splats with their sizes scaled to the probe, no gap fill."""
        factor = (
            (self.probe_factor if self.splat == "world" else 1.0) if scale is None else scale / self.scale
        )
        size = max(1, int(self.point_size_px * factor) | 1) if self.splat == "world" else self.point_size_px
        return RenderParams(
            scale=self.scale * factor,
            point_size_px=size,
            splat=self.splat,
            splat_max_px=max(size, math.ceil(self.splat_max_px * factor)),
            splat_factor=self.splat_factor,
        )

    @property
    def probe_scale(self) -> float:
        """The scale coverage probes render at."""
        return self.probe_settings().scale

    @property
    def per_camera(self) -> int:
        """Candidate views per real camera before rejection."""
        return len(self.vertical_fractions) * (2 if self.mirror else 1) * len(self.forward_fractions)

    def to_dict(self) -> dict[str, JSON]:
        d = asdict(self)
        d["vertical_fractions"] = list(self.vertical_fractions)
        d["forward_fractions"] = list(self.forward_fractions)
        return d

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON]) -> ViewParams:
        """From the JSON form; ViewsError names an unknown key or a wrongly typed value."""
        return parse_spec(cls, doc, "view parameters", ViewsError)
