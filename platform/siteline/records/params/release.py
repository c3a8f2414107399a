"""Release parameters: everything that decides a release's files, recorded identically in the catalog
(``release.parameters["release_params"]``) and the manifest's lineage (``lineage.release_params``)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from typing import Any

from siteline.errors import ReleaseError, SitelineError
from siteline.records.params.pairs import PairParams
from siteline.records.params.presets import PRESETS
from siteline.records.release import FORMAT
from siteline.schema import JSON, json_float, json_int, json_object, json_str

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

    def to_dict(self) -> dict[str, JSON]:
        doc: dict[str, JSON] = {
            "pair": self.pair.to_dict(), "preset": self.preset, "pad": self.pad, "format": self.format,
            "min_image_px": self.min_image_px, "derived": dict(self.derived),
        }  # fmt: skip
        if self.radius_ceiling_m != DEFAULT_RADIUS_CEILING_M:
            doc["radius_ceiling_m"] = self.radius_ceiling_m
        return doc

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON]) -> ReleaseParams:
        unknown = sorted(
            set(doc) - {"pair", "preset", "pad", "format", "min_image_px", "derived", "radius_ceiling_m"}
        )
        if unknown:
            raise ReleaseError(f"release parameters: unknown key(s) {unknown}.")
        preset = doc.get("preset")
        pad = doc.get("pad", True)
        if not isinstance(pad, bool):
            raise ReleaseError(f"release parameters: pad must be true or false, got {pad!r}.")
        return cls(
            PairParams.from_dict(json_object(doc.get("pair", {}), "pair")),
            None if preset is None else json_str(preset, "preset"),
            pad,
            json_int(doc.get("format", FORMAT), "format"),
            json_int(doc.get("min_image_px", 256), "min_image_px"),
            {
                k: json_str(v, f"derived.{k}")
                for k, v in json_object(doc.get("derived") or {}, "derived").items()
            },
            json_float(doc.get("radius_ceiling_m", DEFAULT_RADIUS_CEILING_M), "radius_ceiling_m"),
        )


AUTO = "auto"
AUTO_KNOBS = ("scale", "point_size_px", "views")
# knobs for which "auto" is a value of their own, resolved per pair (colour and shading:
# siteline.render.colour; change_rule: siteline.labels.rule)
VALUE_AUTO_KNOBS = ("colour", "change_rule", "shading")
# the release settings beside the pair knobs
_RELEASE_KEYS = ("preset", "pad", "min_image_px", "radius_ceiling_m")
_PAIR_KNOBS = tuple(f.name for f in fields(PairParams) if f.name != "sampler")


@dataclass(frozen=True)
class ReleaseKnobs:
    """One layer of release settings: a preset, any subset of the pair knobs (PairParams fields;
    ``scale`` and ``point_size_px`` may be ``"auto"``), padding, the smallest long side in pixels a
    release image may have, and the change radius (metres) above which a build warns. ``None`` and
    absent knobs leave the layer below in force."""

    preset: str | None = None
    pair: Mapping[str, JSON] = field(default_factory=dict)
    pad: bool | None = None
    min_image_px: int | None = None
    radius_ceiling_m: float | None = None

    def __post_init__(self) -> None:
        if self.preset is not None and self.preset not in PRESETS:
            raise ReleaseError(f"unknown preset {self.preset!r}; choose one of {sorted(PRESETS)}.")
        unknown = sorted(set(self.pair) - set(_PAIR_KNOBS))
        if unknown:
            raise ReleaseError(f"release settings: unknown knob(s) {unknown}; known: {sorted(_PAIR_KNOBS)}.")
        bad_auto = sorted(
            k for k, v in self.pair.items() if v == AUTO and k not in AUTO_KNOBS + VALUE_AUTO_KNOBS
        )
        if bad_auto:
            raise ReleaseError(
                f"release settings: only {', '.join(AUTO_KNOBS)} may be 'auto', not {bad_auto}."
            )
        try:  # each value checked by the spec that owns it
            PairParams.from_dict({k: v for k, v in self.pair.items() if v != AUTO or k in VALUE_AUTO_KNOBS})
        except SitelineError as exc:
            raise ReleaseError(f"release settings: {exc}") from exc
        if self.pad is not None and not isinstance(self.pad, bool):
            raise ReleaseError(f"release settings: pad must be true or false, got {self.pad!r}.")
        if self.min_image_px is not None and (
            isinstance(self.min_image_px, bool)
            or not isinstance(self.min_image_px, int)
            or self.min_image_px < 1
        ):
            raise ReleaseError(
                f"release settings: min_image_px {self.min_image_px!r} must be a positive integer."
            )
        c = self.radius_ceiling_m
        if c is not None and (isinstance(c, bool) or not isinstance(c, int | float) or not 0 < c < math.inf):
            raise ReleaseError(
                f"release settings: radius_ceiling_m {c!r} must be a positive number of metres."
            )

    @classmethod
    def exactly(cls, params: PairParams, **kw: Any) -> ReleaseKnobs:
        """A layer that sets every pair knob to ``params``'s value (nothing auto, nothing inherited)."""
        return cls(pair={k: v for k, v in params.to_dict().items() if k != "sampler"}, **kw)

    def updated(self, other: ReleaseKnobs, unset: Sequence[str] = ()) -> ReleaseKnobs:
        """This layer with ``other``'s set fields written over it, then the knobs named in ``unset``
        (pair knobs, ``preset``, ``pad``, ``min_image_px``, ``radius_ceiling_m``) removed: what
        ``site update`` stores."""
        pair = {**self.pair, **other.pair}
        doc = {k: v for k, v in self.to_dict().items() if k != "pair"}
        doc |= {k: v for k, v in other.to_dict().items() if k != "pair"}
        for name in unset:
            if name in pair:
                del pair[name]
            elif name in _RELEASE_KEYS:
                doc.pop(name, None)
            elif name not in _PAIR_KNOBS:
                raise ReleaseError(
                    f"--unset {name!r}: not a release setting; known: {sorted(_PAIR_KNOBS)}, {', '.join(_RELEASE_KEYS)}."
                )
        return ReleaseKnobs.from_dict({"pair": pair, **doc})

    def to_dict(self) -> dict[str, JSON]:
        """Only what is set (the site's JSON)."""
        doc: dict[str, JSON] = {"pair": dict(self.pair)} if self.pair else {}
        for name in _RELEASE_KEYS:
            if getattr(self, name) is not None:
                doc[name] = getattr(self, name)
        return doc

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any] | None, source: str = "release settings") -> ReleaseKnobs:
        """A layer as a site's settings or a user's file state it: each value is checked by the
        layer itself (ReleaseError naming it), so any JSON may come in (hence ``Any``)."""
        doc = dict(doc or {})
        unknown = sorted(set(doc) - {"pair", *_RELEASE_KEYS})
        if unknown:
            raise ReleaseError(f"{source}: unknown key(s) {unknown}.")
        if not isinstance(doc.get("pair", {}), Mapping):
            raise ReleaseError(f"{source}: 'pair' must be an object of knobs.")
        return cls(pair=dict(doc.get("pair", {})), **{k: doc.get(k) for k in _RELEASE_KEYS})
