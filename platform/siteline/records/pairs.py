"""A pair's outputs as records: the label-set versions it used, its rendered views, and where its
outputs live (DESIGN.md §4-§6)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any, NamedTuple

from siteline.camera.pinhole import Camera


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
class RenderedView:
    """One view of a pair rendered on both scenes: the synthetic camera (index in the pair's sample,
    parent real image, strategy key, strategy parameters, probe coverage, camera as
    ``schema/camera.schema.json``), its file name in A/, B/ and label/, and what the render found:
    coverage of each scene, valid fraction (neither ignored nor a hole), changed / valid, points read
    from both scenes, the share of pixels ignored for each cause (siteline.codes.IGNORE_CAUSES;
    empty for outputs made before causes were recorded), the share of pixels whose point came from
    the gap fill, and the probe's valid share (an upper bound the view was chosen by)."""

    index: int
    parent: str
    strategy: str
    params: dict[str, Any]
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

    def to_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)} | {"camera": self.camera.to_dict()}

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> RenderedView:
        names = {f.name for f in fields(cls)}
        values = {k: v for k, v in doc.items() if k in names}
        return cls(**values | {"camera": Camera.from_dict(doc["camera"])})


@dataclass(frozen=True)
class PairOutput:
    """A processed pair's outputs in the store at ``root``: the scenes (t1, t2 ids), the change radius
    (metres), the rendered views in index order, the 3D label record (store address, counts,
    checksum, radius details), the label-set versions used, the outputs' key (``digest``: parameters,
    label sets and tilings), the pair parameters (their JSON form), the colour the images show
    (siteline.render.colour.ColourPlan's JSON form; outputs made before it: RGB), the fence views
    were judged against (the site's, or a scene's footprint), the change rule of its labels
    (siteline.labels.rule.ChangeRulePlan's JSON form) and how its views were drawn (``drawn``:
    candidates, how many were probed, and the rejections by reason)."""

    pair_id: int
    t1: int
    t2: int
    radius_m: float
    root: str
    views: tuple[RenderedView, ...]
    labels: dict[str, Any]
    versions: PairVersions
    digest: str
    params: dict[str, Any]
    colour: dict[str, Any] = field(default_factory=lambda: {"source": "rgb"})
    fence: str = "site fence"
    change_rule: dict[str, Any] = field(default_factory=lambda: {"rule": "semantic"})
    drawn: dict[str, Any] = field(default_factory=dict)

    @property
    def view_count(self) -> int:
        return len(self.views)
