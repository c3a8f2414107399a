"""Pair processing parameters: every speed/accuracy knob of labels, views and renders, persisted with
the pair's outputs and a release's lineage."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import ClassVar

from siteline.errors import PairError, SitelineError
from siteline.records.enums import CHANGE_RULES, COLOUR_CHOICES, HOLE_RULES, SHADING_CHOICES, HoleRule
from siteline.records.params.labels import LabelParams
from siteline.records.params.render import WORLD_SPLAT_FACTOR, RenderParams
from siteline.records.params.views import SAMPLER_VERSION, ViewParams
from siteline.records.specs import parse_spec
from siteline.schema import JSON

# changed regions of fewer points are taken back to unchanged (siteline.labels.regions): 3 (on flown
# scans the adaptive rule's few chance flags are single points and pairs, which regions of 3 take back
# as regions of 8 did, while a worker flown at 10 points/m2 has 5-8 returns and a 6 m pole at 80 has
# 24 in pieces, which regions of 8 took back)
MIN_REGION_POINTS = 3
# points whose nearest neighbour lies over this many change radii away are probed against the other
# scene's surface (LabelParams.surface_probe): the pit's ramps at 10 points/m2 recalled 0.89 -> 0.92,
# for 1.1-1.3x the labels' seconds (docs/performance.md)
SURFACE_PROBE = 0.7
# knobs view generation shares with the renders, set once on the pair parameters
_SHARED_VIEW_KNOBS = (
    "scale", "views", "seed", "min_coverage", "min_valid", "point_size_px", "splat", "splat_max_px", "splat_factor",
)  # fmt: skip


@dataclass(frozen=True)
class PairParams:
    """Every knob of pair processing, one name each, composed of the stages' own specs:
    :meth:`render_settings` (``scale``, ``point_size_px``, ``splat``, ``splat_max_px``, ``fill_px``;
    DESIGN.md §6, siteline.records.params.render), :meth:`view_params_spec`
    (``scale``, ``views``, ``seed``, ``min_coverage``, ``point_size_px`` and any other ViewParams
    field in ``view_params``; §5) and :meth:`label_params` (``radius_m``: metres, or None for ``radius_multiplier`` x the median
    spacing of the sparser scene; §4). Each is validated by its own spec when the PairParams is made.
    min_valid: reject a view whose valid fraction (pixels neither ignored nor a hole in either
    scene) is below this: a candidate whose probe of the later scene already shows less is never
    sampled, and a rendered view under it is replaced by the next view of the stratified order
    (``min_coverage`` judges one scene's coverage before rendering; this judges what the pair teaches).
    lod_factor: level of detail read per view (1 = points read at a spacing of half a drawn point,
    ``point_size_px / 2`` pixel footprints, which keeps coverage within a point of reading
    everything; 2 = one drawn point's width); all_points: read
    every point (no level of detail). one_side_hole: a pixel changed on one side and a hole on the
    other is ``ignore`` or ``changed`` (siteline.pairs.render.pair_mask). sampler: the view
    sampler's version (pose snapping and keyed stratified sample, siteline.views.generate), recorded
    in the lineage and part of the outputs' key, so outputs of another sampler are not reused.
    colour: what the A/B images show (``auto``: RGB when both scenes carry it, else intensity, else
    an elevation ramp; or ``rgb``, ``intensity``, ``elevation``: siteline.render.colour); at its
    default ``auto`` it is left out of the digest, so outputs made before it existed keep their key.
    change_rule: whether classes take part in change (``semantic``, DESIGN.md §4) or geometry only
    (``geometry``: a point is changed only when nothing kept lies within the radius); ``auto`` takes
    geometry for a pair whose scenes classify differently (siteline.labels.rule), and is left out of
    the digest like ``colour``. shading: eye-dome lighting of A/B (``edl``, siteline.render.shading;
    ``auto`` and ``none``: none, bench/legible.py); ``auto`` is left out of the digest, and shaded
    outputs get a key of their own (siteline.pairs.plan.output_digest). unsure_edges: with the edge
    trim, a pixel it gave to a farther surface whose change differs from the nearer surface's that
    reached it is ignore (cause ``unsure_edge``: which of the two it shows lies within a point spacing
    of an edge, siteline.pairs.render.unsure_edges), not labelled as the farther surface.
    sparse_surfaces: a surface sparser than its tile (a pole's samples a metre apart, a wall a flight
    grazed; siteline.render.splats.surface_spacing) keeps its changed samples whole in the labels,
    where most of its samples around changed (siteline.labels.store), and with ``unsure_edges`` a
    farther surface drawn between its samples is ignore (cause ``unsure_edge``), not labelled as
    what lies behind the pole.

    The persisted JSON stays flat (the knobs above), so the catalog, the lineage and ``release diff``
    show each knob once under its one name."""

    scale: float = 0.125
    point_size_px: int = 1
    views: int = 300
    radius_m: float | None = None
    radius_multiplier: float = 2.5
    lod_factor: float = 1.0
    seed: int = 0
    min_coverage: float = 0.5
    min_valid: float = 0.7
    view_params: dict[str, JSON] = field(default_factory=dict)
    one_side_hole: HoleRule = "ignore"
    all_points: bool = False
    sampler: str = SAMPLER_VERSION
    colour: str = "auto"
    change_rule: str = "auto"
    splat: str = "world"
    splat_max_px: int = 31
    fill_px: int = 2
    label_rule: str = "adaptive"
    min_region_points: int = MIN_REGION_POINTS
    splat_factor: float = WORLD_SPLAT_FACTOR
    trim_edges: bool = True
    shading: str = "auto"
    surface_probe: float = SURFACE_PROBE
    unsure_edges: bool = True
    sparse_surfaces: bool = True

    # what each knob added after the first release meant before it existed (a record without it)
    BEFORE: ClassVar[Mapping[str, object]] = {
        "splat": "fixed", "splat_max_px": 31, "fill_px": 0, "min_valid": 0.25, "label_rule": "nearest",
        "min_region_points": 1, "splat_factor": WORLD_SPLAT_FACTOR, "trim_edges": False,
        "shading": "none", "surface_probe": 0.0, "unsure_edges": False, "sparse_surfaces": False,
    }  # fmt: skip

    def __post_init__(self) -> None:
        if self.sampler != SAMPLER_VERSION:
            raise PairError(
                f"view sampler {self.sampler!r} is not this version's ({SAMPLER_VERSION!r}); outputs of "
                "another sampler cannot be rebuilt: drop the 'sampler' key to use the current one."
            )
        if not 0.0 <= self.min_valid <= 1.0:
            raise PairError(f"min_valid {self.min_valid} must lie in [0, 1].")
        if self.colour not in COLOUR_CHOICES:
            raise PairError(f"colour {self.colour!r}: use one of {', '.join(COLOUR_CHOICES)}.")
        if self.shading not in SHADING_CHOICES:
            raise PairError(f"shading {self.shading!r}: use one of {', '.join(SHADING_CHOICES)}.")
        if self.change_rule not in CHANGE_RULES:
            raise PairError(f"change rule {self.change_rule!r}: use one of {', '.join(CHANGE_RULES)}.")
        if self.one_side_hole not in HOLE_RULES:
            raise PairError(f"one_side_hole {self.one_side_hole!r}: use one of {HOLE_RULES}.")
        clash = sorted(set(self.view_params) & set(_SHARED_VIEW_KNOBS))
        if clash:
            raise PairError(
                f"view_params {clash}: set these knobs on the pair parameters themselves (one name each)."
            )
        try:
            self.render_settings(), self.view_params_spec(), self.label_params()
        except SitelineError as exc:
            raise PairError(f"pair parameters: {exc}") from exc

    def render_settings(self) -> RenderParams:
        """The render knobs as the renderer's own spec."""
        return RenderParams(
            scale=self.scale,
            point_size_px=self.point_size_px,
            splat=self.splat,
            splat_max_px=self.splat_max_px,
            fill_px=self.fill_px,
            splat_factor=self.splat_factor,
            trim_edges=self.trim_edges,
            sparse_surfaces=self.sparse_surfaces and self.unsure_edges,
        )

    def view_params_spec(self) -> ViewParams:
        """The view-generation knobs as ViewParams (``view_params`` holds the less common ones)."""
        base: dict[str, JSON] = {
            "views": self.views,
            "seed": self.seed,
            "scale": self.scale,
            "min_coverage": self.min_coverage,
            "min_valid": self.min_valid,
            "point_size_px": self.point_size_px,
            "splat": self.splat,
            "splat_max_px": self.splat_max_px,
            "splat_factor": self.splat_factor,
        }
        return ViewParams.from_dict({**base, **self.view_params})

    def label_params(self) -> LabelParams:
        """The change-label knobs as LabelParams."""
        return LabelParams(
            self.radius_m, self.radius_multiplier, self.label_rule, self.min_region_points, self.surface_probe,
            self.sparse_surfaces,
        )  # fmt: skip

    def to_dict(self) -> dict[str, JSON]:
        return asdict(self)

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON]) -> PairParams:
        """From the JSON form; PairError names an unknown key or a wrongly typed value."""
        return parse_spec(cls, doc, "pair parameters", PairError)

    @classmethod
    def from_record(cls, doc: Mapping[str, JSON]) -> PairParams:
        """The parameters a record (a release's lineage or catalog row) says outputs were made with, to
        describe them: a knob it lacks has the value it meant before it existed (:attr:`BEFORE`), and
        its sampler is not checked (the outputs are read, not rebuilt). PairError as :meth:`from_dict`."""
        return parse_spec(
            cls, {**cls.BEFORE, **doc, "sampler": SAMPLER_VERSION}, "pair parameters", PairError
        )

    def digest(self) -> str:
        """Short stable hash naming this parameter set's outputs."""
        doc = self.to_dict()
        # auto: resolved per pair, outputs made before keep their key
        for knob in ("colour", "change_rule", "shading"):
            if doc[knob] == "auto":
                del doc[knob]
        if doc["splat_factor"] == WORLD_SPLAT_FACTOR:  # the renders of before: their key is kept
            del doc["splat_factor"]
        if doc["surface_probe"] == 0 or doc["label_rule"] == "nearest":  # no probe: the labels of before
            del doc["surface_probe"]
        if not doc["unsure_edges"]:  # the masks of before
            del doc["unsure_edges"]
        else:  # its second version: the rims of a farther change too (siteline.pairs.render.occluding_rims)
            doc["unsure_edges"] = 2
        if not doc["sparse_surfaces"]:  # the labels and masks of before
            del doc["sparse_surfaces"]
        elif self.unsure_edges:  # masks of its third version: behind sparse unchanged surfaces too (2),
            doc["sparse_surfaces"] = 3  # sparse in cells of two sizes, half a spacing behind (3)
        if doc["trim_edges"]:  # its second version: a surface's own points within 5 spacings in depth
            doc["trim_edges"] = 2  # (not a tenth of the depth), lines kept (siteline.render.edges)
        if doc["label_rule"] == "adaptive":  # its third version (siteline.labels.change: held_by_any, grazed)
            doc["label_rule"] = "adaptive3"
        return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:12]
