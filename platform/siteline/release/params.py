"""Release parameters: everything that decides a release's files, recorded identically in the catalog
(``release.parameters["release_params"]``) and the manifest's lineage (``lineage.release_params``)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from siteline.errors import ReleaseError
from siteline.pairs.params import PairParams
from siteline.release.layout import FORMAT
from siteline.schema import JsonObject

# the change radius above which a build warns: a pair then labels smaller changes unchanged
DEFAULT_RADIUS_CEILING_M = 1.0


@dataclass(frozen=True)
class ReleaseParams:
    """pair: the pair-processing parameters (after the preset). preset: its name, or None. pad: images
    padded to multiples of 32 and at least 256 px. format: the release layout (2). min_image_px: the
    smallest long side a release image may have (a build under it is refused). derived: knob ->
    how an ``auto`` knob was worked out (siteline.release.knobs), recorded in the lineage.
    radius_ceiling_m: a pair whose change radius (the smallest change it resolves) is above this is
    warned of at build and marked in the datasheet (it does not change any file, so it is left out of
    the JSON at its default and releases built before it keep their parameters)."""

    pair: PairParams = field(default_factory=PairParams)
    preset: str | None = None
    pad: bool = True
    format: int = FORMAT
    min_image_px: int = 256
    derived: Mapping[str, str] = field(default_factory=dict)
    radius_ceiling_m: float = DEFAULT_RADIUS_CEILING_M

    def __post_init__(self) -> None:
        if self.format != FORMAT:
            raise ReleaseError(f"release format {self.format!r}: this siteline builds format {FORMAT}.")
        if not isinstance(self.pad, bool):
            raise ReleaseError(f"pad must be true or false, got {self.pad!r}.")

    def to_dict(self) -> JsonObject:
        doc: JsonObject = {
            "pair": self.pair.to_dict(), "preset": self.preset, "pad": self.pad, "format": self.format,
            "min_image_px": self.min_image_px, "derived": dict(self.derived),
        }  # fmt: skip
        if self.radius_ceiling_m != DEFAULT_RADIUS_CEILING_M:
            doc["radius_ceiling_m"] = self.radius_ceiling_m
        return doc

    @classmethod
    def from_dict(cls, doc: JsonObject) -> ReleaseParams:
        unknown = sorted(
            set(doc) - {"pair", "preset", "pad", "format", "min_image_px", "derived", "radius_ceiling_m"}
        )
        if unknown:
            raise ReleaseError(f"release parameters: unknown key(s) {unknown}.")
        return cls(
            PairParams.from_dict(doc.get("pair", {})),
            doc.get("preset"),
            doc.get("pad", True),
            doc.get("format", FORMAT),
            doc.get("min_image_px", 256),
            dict(doc.get("derived") or {}),
            float(doc.get("radius_ceiling_m", DEFAULT_RADIUS_CEILING_M)),
        )
