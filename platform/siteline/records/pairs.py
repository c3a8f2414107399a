"""A pair's outputs as records: the label-set versions it used, its rendered views, and where its
outputs live (DESIGN.md §4-§6)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Literal, NamedTuple, NotRequired, TypedDict, get_args

import numpy as np

from siteline.camera.pinhole import Camera
from siteline.errors import PairError
from siteline.records.params.pairs import PairParams
from siteline.schema import (
    JSON,
    json_float,
    json_int,
    json_list,
    json_number,
    json_object,
    json_or_none,
    json_str,
)
from siteline.site.taxonomy import Taxonomy


class PairVersions(NamedTuple):
    """The label-set versions of a pair's earlier (t1) and later (t2) scene."""

    t1: int
    t2: int

    def to_dict(self) -> dict[str, int]:
        return {"t1": self.t1, "t2": self.t2}

    @classmethod
    def from_dict(cls, doc: Mapping[str, int] | None) -> PairVersions:
        """From ``{"t1": v1, "t2": v2}``; outputs written before label sets were versioned used 1."""
        doc = doc or {}
        return cls(int(doc.get("t1", 1)), int(doc.get("t2", 1)))


@dataclass(frozen=True)
class ViewStrategy:
    """How a synthetic view was made from its parent camera (DESIGN.md §5): lowered to
    ``vertical_fraction`` of its height, ``mirrored`` across the fence segment ``mirror_segment_m``
    ((x, y) ends, site-local metres) by ``mirror_rule``, then stepped ``forward_fraction`` of the
    central depth ``central_depth_m`` (``forward_m`` metres; None where the view could not be made)."""

    vertical_fraction: float
    mirrored: bool
    forward_fraction: float
    mirror_segment_m: tuple[tuple[float, float], tuple[float, float]] | None = None
    mirror_rule: str | None = None
    central_depth_m: float | None = None
    forward_m: float | None = None

    def to_dict(self) -> dict[str, JSON]:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON]) -> ViewStrategy:
        seg = doc.get("mirror_segment_m")
        segment = None
        if seg:
            a, b = (json_list(end, "mirror_segment_m") for end in json_list(seg, "mirror_segment_m"))
            segment = (
                (json_float(a[0]), json_float(a[1])),
                (json_float(b[0]), json_float(b[1])),
            )
        return cls(
            json_float(doc["vertical_fraction"], "vertical_fraction"), bool(doc["mirrored"]),
            json_float(doc["forward_fraction"], "forward_fraction"), segment,
            json_or_none(json_str, doc.get("mirror_rule"), "mirror_rule"),
            json_or_none(json_number, doc.get("central_depth_m"), "central_depth_m"),
            json_or_none(json_number, doc.get("forward_m"), "forward_m"),
        )  # fmt: skip


@dataclass(frozen=True)
class RenderedView:
    """One view of a pair rendered on both scenes: the synthetic camera (index in the pair's sample,
        parent real image, strategy key, strategy parameters, probe coverage, camera as
        ``schema/camera.schema.json``), its file name in A/, B/ and label/, and what the render found:
        coverage of each scene, valid fraction (neither ignored nor a hole), changed / valid, points read
        from both scenes, the share of pixels ignored for each cause (siteline.codes.IGNORE_CAUSES;
        empty for outputs made before causes were recorded), the share of pixels whose point came from
        the gap fill, and the probe's valid share (an upper bound the view was chosen by), and the share of its changed pixels
    whose colour differs between A and B (siteline.pairs.render.change_visibility; None: nothing
    changed, or made before it was measured)."""

    index: int
    parent: str
    strategy: str
    params: ViewStrategy
    coverage: float | None
    camera: Camera
    file: str
    coverage_a: float
    coverage_b: float
    valid: float
    change_ratio: float
    points_read: int
    ignore: dict[str, float] = field(default_factory=dict)
    filled: float = 0.0
    probe_valid: float | None = None
    change_visible: float | None = None

    def to_dict(self) -> dict[str, JSON]:
        return {f.name: getattr(self, f.name) for f in fields(self)} | {
            "params": self.params.to_dict(),
            "camera": self.camera.to_dict(),
        }

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON]) -> RenderedView:
        """From :meth:`to_dict`'s form; KeyError or TypeError where it is not one."""
        return cls(
            index=json_int(doc["index"], "index"), parent=json_str(doc["parent"], "parent"),
            strategy=json_str(doc["strategy"], "strategy"),
            params=ViewStrategy.from_dict(json_object(doc["params"], "params")),
            coverage=json_or_none(json_number, doc.get("coverage"), "coverage"),
            camera=Camera.from_dict(doc["camera"]), file=json_str(doc["file"], "file"),
            coverage_a=json_number(doc["coverage_a"], "coverage_a"), coverage_b=json_number(doc["coverage_b"], "coverage_b"),
            valid=json_number(doc["valid"], "valid"), change_ratio=json_number(doc["change_ratio"], "change_ratio"),
            points_read=json_int(doc["points_read"], "points_read"),
            ignore={k: json_number(v, f"ignore.{k}") for k, v in json_object(doc.get("ignore") or {}, "ignore").items()},
            filled=json_number(doc.get("filled", 0.0), "filled"),
            probe_valid=json_or_none(json_number, doc.get("probe_valid"), "probe_valid"),
            change_visible=json_or_none(json_number, doc.get("change_visible"), "change_visible"),
        )  # fmt: skip


ColourSource = Literal["rgb", "height", "intensity", "elevation"]
# height above the pair's ground (siteline.views.ground) on the ramp, metres: one fixed stretch for every
# pair and release, so a colour is a height everywhere (trees, buildings and cranes up to 25 m apart)
HEIGHT_RANGE_M = (0.0, 25.0)
# the elevation ramp: low -> high, five stops of viridis (perceptually uniform, readable in grey)
RAMP = np.array([[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]], dtype=np.float64)


@dataclass(frozen=True)
class ColourPlan:
    """A pair's colour: ``source``, and for intensity each scene's (low, high) stretch, for elevation
    the pair's (low, high) site-local z stretch (metres) used for both scenes, for height the
    (low, high) height above the pair's ground (metres, :data:`HEIGHT_RANGE_M`); ``why`` says how
    ``auto`` chose; ``shading``: ``edl`` (eye-dome lighting over the colour) or ``none``."""

    source: ColourSource
    stretch_t1: tuple[float, float] | None = None
    stretch_t2: tuple[float, float] | None = None
    why: str = ""
    shading: str = "none"

    @property
    def attribute(self) -> str | None:
        """The tile attribute the colour is made from (None: from the points' z, or for height from
        their height above the ground, which the caller gives)."""
        return {"rgb": "rgb", "intensity": "intensity", "elevation": None, "height": None}[self.source]

    def colours(self, side: int, xyz: np.ndarray, values: np.ndarray | None) -> np.ndarray:
        """(N, 3) uint8 colour of scene ``side`` (1 or 2)'s points: their RGB, or their ``values``
        (intensity; for height their heights above the ground, metres) or z stretched between this
        plan's bounds onto the grey scale (intensity) or the ramp."""
        if self.source in ("rgb", "height") and values is None:
            raise PairError(
                f"a {self.source} colour plan needs the points' {'rgb' if self.source == 'rgb' else 'heights'}."
            )
        if self.source == "rgb":
            return values  # type: ignore[return-value]
        lo, hi = (self.stretch_t1 if side == 1 else self.stretch_t2) or (0.0, 1.0)
        data = np.asarray(values if self.source in ("intensity", "height") else xyz[:, 2], dtype=np.float64)
        t = np.clip((data - lo) / max(hi - lo, 1e-9), 0.0, 1.0) if len(data) else data
        if self.source == "intensity":
            grey = np.rint(t * 255.0).astype(np.uint8)
            return np.repeat(grey[:, None], 3, axis=1)
        pos = t * (len(RAMP) - 1)
        return np.rint(
            np.stack([np.interp(pos, np.arange(len(RAMP)), RAMP[:, c]) for c in range(3)], axis=1)
        ).astype(np.uint8)

    @property
    def look(self) -> str:
        """What sets these images apart from the intensity or RGB images of before, for the outputs'
        key: ``edl``, ``height``, ``edl:height``, or ``none``."""
        parts = [self.shading] if self.shading != "none" else []
        parts += ["height"] if self.source == "height" else []
        return ":".join(parts) or "none"

    def to_dict(self) -> dict[str, JSON]:
        doc: dict[str, JSON] = {
            "source": self.source,
            "stretch_t1": list(self.stretch_t1) if self.stretch_t1 else None,
            "stretch_t2": list(self.stretch_t2) if self.stretch_t2 else None,
            "why": self.why,
        }
        return doc | ({"shading": self.shading} if self.shading != "none" else {})  # unshaded plans as before

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON]) -> ColourPlan:
        """From :meth:`to_dict`'s form (a pair's or a release lineage's ``colour``)."""
        source = next((c for c in get_args(ColourSource) if c == doc.get("source", "rgb")), None)
        if source is None:
            raise PairError(
                f"colour source {doc.get('source')!r}: use one of {', '.join(get_args(ColourSource))}."
            )

        def bounds(v: JSON) -> tuple[float, float] | None:
            return (json_float(json_list(v)[0]), json_float(json_list(v)[1])) if v else None

        return cls(
            source, bounds(doc.get("stretch_t1")), bounds(doc.get("stretch_t2")), str(doc.get("why", "")),
            str(doc.get("shading", "none")),
        )  # fmt: skip


@dataclass(frozen=True)
class ChangeRulePlan:
    """The rule a pair's change labels use: ``semantic`` (a point is changed when its nearest
    counterpart has another class, DESIGN.md §4) or ``geometry`` (changed only when it has no
    counterpart of a kept class within the radius, whatever the classes); ``why`` says how it was
    chosen, ``differences`` how the two scenes' schemes differ."""

    rule: str = "semantic"
    why: str = ""
    differences: tuple[str, ...] = field(default_factory=tuple)

    def geometric_lut(self, taxonomy: Taxonomy) -> np.ndarray:
        """(256,) bool of the classes compared by geometry only (siteline.labels.change.change_flags)."""
        if self.rule == "geometry":
            return np.ones(256, dtype=bool)
        return taxonomy.geometry_only_lut()

    def ground_lut(self, taxonomy: Taxonomy) -> np.ndarray | None:
        """(256,) bool of the ground classes the adaptive rule may trust (siteline.labels.change), None
        under the geometry rule (the scenes' classes disagree)."""
        return None if self.rule == "geometry" else taxonomy.ground_lut()

    def to_dict(self) -> dict[str, JSON]:
        return {"rule": self.rule, "why": self.why, "differences": list(self.differences)}

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON] | None) -> ChangeRulePlan:
        """From the JSON form; outputs made before the rule was recorded used the semantic rule."""
        if not doc:
            return cls("semantic", "made before the change rule was recorded")
        differences = tuple(
            json_str(d, "differences") for d in json_list(doc.get("differences", ()), "differences")
        )
        return cls(str(doc["rule"]), str(doc.get("why", "")), differences)


@dataclass(frozen=True)
class RadiusChoice:
    """How a pair's change radius was chosen: each scene's median point spacing (metres, ``t1``/``t2``),
    the multiplier of the sparser one's, whether the radius was given (the multiplier is then what it
    amounts to), and the expected false change on unchanged surfaces at that multiplier (siteline.records.params.labels)."""

    median_spacing_m: Mapping[str, float]
    multiplier: float
    given: bool = False
    expected_false_change: Mapping[str, float | str] | None = None

    def to_dict(self) -> dict[str, JSON]:
        doc: dict[str, JSON] = {
            "median_spacing_m": dict(self.median_spacing_m),
            "multiplier": self.multiplier,
        }
        if self.given:
            doc["given"] = True
        if self.expected_false_change is not None:
            doc["expected_false_change"] = dict(self.expected_false_change)
        return doc

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON]) -> RadiusChoice:
        spacing = json_object(doc.get("median_spacing_m") or {}, "median_spacing_m")
        false_change = json_or_none(json_object, doc.get("expected_false_change"), "expected_false_change")
        return cls(
            {k: json_number(v, f"median_spacing_m.{k}") for k, v in spacing.items()},
            json_float(doc.get("multiplier", float("nan")), "multiplier"), bool(doc.get("given", False)),
            None if false_change is None else
            {k: v if isinstance(v, str) else json_number(v, f"expected_false_change.{k}") for k, v in false_change.items()},
        )  # fmt: skip


@dataclass(frozen=True)
class ChangeLabels:
    """A pair's 3D change labels: the label store's address, the radius (metres), the points of each
    scene (``t1``, ``t2``) by label (``unchanged``, ``changed``, ``ignored``), the store's checksum, the
    seconds they took (None: made by an earlier run), their points, and how the radius was chosen."""

    uri: str
    radius_m: float
    counts: Mapping[str, Mapping[str, int]]
    checksum: str
    seconds: float | None
    points: int
    radius: RadiusChoice | None = None

    def to_dict(self) -> dict[str, JSON]:
        doc: dict[str, JSON] = {"uri": self.uri, "radius_m": self.radius_m, "counts": {k: dict(v) for k, v in self.counts.items()},
                               "checksum": self.checksum}  # fmt: skip
        if self.seconds is not None:
            doc["seconds"] = self.seconds
        doc["points"] = self.points
        if self.radius is not None:
            doc["radius"] = self.radius.to_dict()
        return doc

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON]) -> ChangeLabels:
        counts = {
            k: {
                label: json_int(n, f"counts.{k}.{label}")
                for label, n in json_object(v, f"counts.{k}").items()
            }
            for k, v in json_object(doc.get("counts") or {}, "counts").items()
        }
        points = doc.get("points")
        radius = doc.get("radius")
        return cls(
            str(doc.get("uri", "")), json_float(doc["radius_m"], "radius_m"), counts,
            str(doc.get("checksum", "")), json_or_none(json_number, doc.get("seconds"), "seconds"),
            json_int(points, "points") if points is not None else sum(n for side in counts.values() for n in side.values()),
            RadiusChoice.from_dict(json_object(radius, "radius")) if radius else None,
        )  # fmt: skip


# why candidate views were rejected, in words (siteline.views.generate; the datasheet's)
REJECTED_WORDS = {
    "outside_fence": "outside the fence after mirroring", "underground": "underground",
    "near_surface": "too near a point of either scene", "under_geometry": "under geometry", "low_coverage": "too little coverage",
    "low_valid_probe": "too few valid pixels in their probe", "low_valid": "too few valid pixels rendered",
    "no_fence": "no fence to mirror across", "nothing_ahead": "nothing ahead to step towards",
    "sparse_points": "drawn from points too far apart",
}  # fmt: skip
# why a changed region is in fewer views than asked (siteline.views.generate.cover_changes); and
# ``only:<rejection>``: every candidate that frames it was rejected, most of them for that reason
UNSEEN_REASONS = {
    "too_small": "too small or too far to reach the pixels asked from any candidate",
    "outside_fence": "outside the fence",
    "hidden": "hidden from every candidate that frames it (behind other surfaces)",
    "view_budget": "the views that may be chosen for changes were spent on others",
    "low_valid": "views that showed it rendered too few valid pixels",
}


def unseen_words(reason: str) -> str:
    """A region's ``reason`` (:data:`UNSEEN_REASONS`, or ``only:<rejection>``) in words."""
    if reason.startswith("only:"):
        why = reason.removeprefix("only:")
        return f"every candidate that frames it was rejected, most as {REJECTED_WORDS.get(why, why)}"
    return UNSEEN_REASONS.get(reason, reason)


@dataclass(frozen=True)
class ChangedRegion:
    """One changed region of a pair as its views were planned around it (siteline.pairs.regions):
    its number (1 = the largest), the scenes whose changed points it holds (``t1``: gone or moved
    away, ``t2``: new or moved in), its surface (m2: the 0.5 m cells, or change-radius cells where larger, its points
    fill, with those a sparse scan left empty between them; a small region's is rounded up to
    cells), its
    centre and extent (site-local metres), the indices of the views planned to show it (at least
    the pixels asked, in front of what the later scene's probe drew), and why fewer than asked do
    (None: enough; :func:`unseen_words`)."""

    id: int
    sides: tuple[str, ...]
    area_m2: float
    center_m: tuple[float, float, float]
    size_m: tuple[float, float, float]
    views: tuple[int, ...] = ()
    reason: str | None = None

    def to_dict(self) -> dict[str, JSON]:
        return {
            "id": self.id, "sides": list(self.sides), "area_m2": round(self.area_m2, 2),
            "center_m": [round(v, 2) for v in self.center_m], "size_m": [round(v, 2) for v in self.size_m],
            "views": list(self.views), "reason": self.reason,
        }  # fmt: skip

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON]) -> ChangedRegion:
        center = [json_number(v, "center_m") for v in json_list(doc["center_m"], "center_m")]
        size = [json_number(v, "size_m") for v in json_list(doc["size_m"], "size_m")]
        return cls(
            json_int(doc["id"], "id"), tuple(json_str(v, "sides") for v in json_list(doc["sides"], "sides")),
            json_number(doc["area_m2"], "area_m2"), (center[0], center[1], center[2]), (size[0], size[1], size[2]),
            tuple(json_int(v, "views") for v in json_list(doc.get("views") or [], "views")),
            json_or_none(json_str, doc.get("reason"), "reason"),
        )  # fmt: skip


class ChangesDoc(TypedDict):
    """:class:`ChangesSeen` as JSON."""

    asked_views: int
    min_px: int
    min_m2: float
    smaller: int
    regions: list[dict[str, JSON]]


@dataclass(frozen=True)
class ChangesSeen:
    """How a pair's views cover its changes: each region of at least ``min_m2`` square metres was to
    be in ``asked_views`` views at ``min_px`` pixels or more (at the render scale); ``smaller``:
    regions under ``min_m2`` (not planned for)."""

    asked_views: int
    min_px: int
    min_m2: float
    smaller: int
    regions: tuple[ChangedRegion, ...]

    def to_dict(self) -> ChangesDoc:
        return {
            "asked_views": self.asked_views, "min_px": self.min_px, "min_m2": self.min_m2, "smaller": self.smaller,
            "regions": [r.to_dict() for r in self.regions],
        }  # fmt: skip

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON]) -> ChangesSeen:
        return cls(
            json_int(doc["asked_views"], "asked_views"), json_int(doc["min_px"], "min_px"),
            json_number(doc["min_m2"], "min_m2"), json_int(doc["smaller"], "smaller"),
            tuple(ChangedRegion.from_dict(json_object(r, "regions")) for r in json_list(doc["regions"], "regions")),
        )  # fmt: skip

    @property
    def short(self) -> list[ChangedRegion]:
        """The regions in fewer views than asked."""
        return [r for r in self.regions if len(r.views) < self.asked_views]

    def summary(self, most: int = 12) -> str:
        """In words: the regions, the views that show each, and why some show in fewer than asked."""
        if not self.regions:
            return f"no changed region of {self.min_m2:g} m2 or more" + (
                f" ({self.smaller} smaller)" if self.smaller else ""
            )
        fewest = min(len(r.views) for r in self.regions)
        head = (
            f"{len(self.regions)} changed region{'' if len(self.regions) == 1 else 's'} of {self.min_m2:g} m2 or more, each asked in "
            f"{self.asked_views} views at {self.min_px} px or more; "
            + (
                f"all shown (fewest views {fewest})"
                if not self.short
                else f"{len(self.regions) - len(self.short)} shown, {len(self.short)} in fewer"
            )
        )
        listed = sorted(self.regions, key=lambda r: (len(r.views) >= self.asked_views, r.id))[:most]
        parts = [
            f"#{r.id} {r.area_m2:.1f} m2 at ({r.center_m[0]:.1f}, {r.center_m[1]:.1f}, {r.center_m[2]:.1f}) "
            f"[{'+'.join(r.sides)}]: {len(r.views)} view{'' if len(r.views) == 1 else 's'}"
            + (f" ({unseen_words(r.reason)})" if r.reason else "")
            for r in listed
        ]
        more = len(self.regions) - len(listed)
        tail = f"; {more} more" if more else ""
        small = f"; {self.smaller} smaller regions not planned for" if self.smaller else ""
        return head + ": " + "; ".join(parts) + tail + small


class DrawnDoc(TypedDict):
    """:class:`Drawn` as a pair's summary and a release's lineage hold it."""

    candidates: int
    probed: NotRequired[int]
    rejected: NotRequired[dict[str, int]]
    changes: NotRequired[ChangesDoc]


@dataclass(frozen=True)
class Drawn:
    """How a pair's views were drawn: candidates made, how many were probed (None: not recorded), the
    rejected candidates by reason, and how the views cover the pair's changed regions (None: drawn
    without them)."""

    candidates: int
    probed: int | None
    rejected: Mapping[str, int]
    changes: ChangesSeen | None = None

    def to_dict(self) -> DrawnDoc:
        doc: DrawnDoc = {"candidates": self.candidates}
        if self.probed is not None:
            doc["probed"] = self.probed
        doc["rejected"] = dict(self.rejected)
        if self.changes is not None:
            doc["changes"] = self.changes.to_dict()
        return doc

    @classmethod
    def from_dict(cls, doc: Mapping[str, object]) -> Drawn | None:
        """From a pair summary's ``candidates``, ``probed``, ``rejected`` and ``changes``; None when it
        has none."""
        if "candidates" not in doc:
            return None
        rejected = json_object(doc.get("rejected") or {}, "rejected")
        changes = doc.get("changes")
        return cls(
            json_int(doc["candidates"], "candidates"),
            json_or_none(json_int, doc.get("probed"), "probed"),
            {k: json_int(n, f"rejected.{k}") for k, n in rejected.items()},
            ChangesSeen.from_dict(json_object(changes, "changes")) if changes else None,
        )


@dataclass(frozen=True)
class GroundUsed:
    """The ground a pair's views stood on: ``model`` (``plane`` or ``terrain``), where its points came
    from (``class``, or ``morphology`` with the filter's params), how many and what share of the
    points read, how far the terrain rises above the best plane (95th percentile) and the tolerance
    under which the plane is kept (metres), and the terrain's cell (metres; None for a plane)."""

    model: str
    source: str
    ground_points: int
    share: float
    residual_m: float
    tolerance_m: float
    filter: Mapping[str, JSON] | None = None
    cell_m: float | None = None

    def to_dict(self) -> dict[str, JSON]:
        return {
            "model": self.model, "source": self.source, "ground_points": self.ground_points, "share": self.share,
            "residual_m": self.residual_m, "tolerance_m": self.tolerance_m,
            "filter": dict(self.filter) if self.filter is not None else None, "cell_m": self.cell_m,
        }  # fmt: skip

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON] | None) -> GroundUsed | None:
        """From a pair summary's ``ground``; None for outputs made before it was recorded."""
        if not doc:
            return None
        cell = doc.get("cell_m", json_object(doc.get("terrain") or {}, "terrain").get("cell_m"))
        return cls(
            str(doc["model"]), str(doc["source"]), json_int(doc["ground_points"], "ground_points"),
            json_float(doc["share"], "share"), json_float(doc["residual_m"], "residual_m"),
            json_float(doc["tolerance_m"], "tolerance_m"), json_or_none(json_object, doc.get("filter"), "filter"),
            None if cell is None else json_float(cell, "cell_m"),
        )  # fmt: skip

    def summary(self) -> str:
        """In words, for a datasheet."""
        found = (
            "the ground class"
            if self.source == "class"
            else "ground found from the points' shape (progressive morphological filter, "
            + ", ".join(f"{k} {v:g}" for k, v in (self.filter or {}).items())
            + "; no usable ground class)"
        )
        shape = (
            f"a plane (the terrain rises above it by {self.residual_m:.2f} m, within the {self.tolerance_m:g} m "
            "tolerance)"
            if self.model == "plane"
            else f"a terrain grid of {self.cell_m:.1f} m cells (the terrain rises above the best plane by "
            f"{self.residual_m:.1f} m, over the {self.tolerance_m:g} m tolerance)"
        )
        return f"views stand on {shape}, from {found}: {self.ground_points:,} points, {self.share:.0%} of those read"


class PairSummary(TypedDict):
    """A pair's ``summary.json`` (siteline.pairs.execute): its scenes, radius (metres), the documents of
    its parameters (PairParams), label sets, labels (ChangeLabels), ground (GroundUsed, and the plane
    its views stood on), fence, colour (ColourPlan), change rule (ChangeRulePlan), how its views were
    drawn (DrawnDoc's keys) and each rendered view (RenderedView). Keys added since the first outputs
    may be absent from earlier ones."""

    pair: int
    t1: int
    t2: int
    radius_m: float
    params: dict[str, JSON]
    label_sets: NotRequired[dict[str, int]]
    labels: dict[str, JSON]
    ground_plane: NotRequired[dict[str, JSON]]
    ground: NotRequired[dict[str, JSON] | None]
    fence: NotRequired[str]
    colour: NotRequired[dict[str, JSON]]
    change_rule: NotRequired[dict[str, JSON] | None]
    candidates: NotRequired[int]
    probed: NotRequired[int | None]
    rejected: NotRequired[dict[str, int]]
    changes: NotRequired[ChangesDoc]
    views: list[dict[str, JSON]]


@dataclass(frozen=True)
class PairOutput:
    """A processed pair's outputs in the store at ``root``: the scenes (t1, t2 ids), the change radius
    (metres), the rendered views in index order, the 3D label record (store address, counts,
    checksum, radius details), the label-set versions used, the outputs' key (``digest``: parameters,
    label sets and tilings), the pair parameters, the colour the images show
    (outputs made before it: RGB), the fence views were judged against (the site's, or a scene's
    footprint), the change rule of its labels, how its views were drawn and the ground they stood on
    (None: not recorded)."""

    pair_id: int
    t1: int
    t2: int
    radius_m: float
    root: str
    views: tuple[RenderedView, ...]
    labels: ChangeLabels
    versions: PairVersions
    digest: str
    params: PairParams
    colour: ColourPlan = ColourPlan("rgb")
    fence: str = "site fence"
    change_rule: ChangeRulePlan = ChangeRulePlan()
    drawn: Drawn | None = None
    ground: GroundUsed | None = None

    @property
    def view_count(self) -> int:
        return len(self.views)
