"""The LAS scan: what ingest's one pass over a mission's point cloud found."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Literal, cast, get_args

import numpy as np

from siteline.schema import (
    JSON,
    json_bool,
    json_float,
    json_int,
    json_list,
    json_number,
    json_numbers,
    json_object,
    json_or_none,
    json_str,
)
from siteline.site.crs import ZUnit

# how a scan names a file's colour, and whether it is 0-255 in 16-bit fields
COLOUR_NAMES = {True: "rgb 8-bit stored in 16-bit fields", False: "rgb 16-bit"}
EIGHT_BIT = {name: eight for eight, name in COLOUR_NAMES.items()}
# the percentiles a scene's intensity and elevation are stretched between when rendered as colour
STRETCH_PERCENTILES = (2.0, 98.0)
RgbContent = Literal["varies", "constant", "absent"]


@dataclass(frozen=True)
class ColourStats:
    """Whether a scene's RGB carries information ("varies"; "constant": every point the same colour,
    all-zero included; "absent": the point format has none), and the 2nd-98th percentile stretches
    of its intensity (None when constant) and of its site-local z (metres), from the scan's sample."""

    rgb: RgbContent
    intensity_range: tuple[float, float] | None
    z_range_m: tuple[float, float]

    def to_dict(self) -> dict[str, JSON]:
        return {
            "rgb": self.rgb,
            "intensity_range": list(self.intensity_range) if self.intensity_range else None,
            "z_range_m": list(self.z_range_m),
        }

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON]) -> ColourStats:
        rgb = doc["rgb"]
        if rgb not in get_args(RgbContent):
            raise ValueError(f"rgb {rgb!r} is none of {', '.join(get_args(RgbContent))}")
        ir = json_list(doc.get("intensity_range") or (), "intensity_range")
        z = json_list(doc["z_range_m"], "z_range_m")
        return cls(
            cast(RgbContent, rgb), (json_float(ir[0]), json_float(ir[1])) if ir else None,
            (json_float(z[0]), json_float(z[1])),
        )  # fmt: skip


# the kind of surface of each point of a co-registration sample (its fourth column): stable surfaces
# fix what point-to-plane ICP can, structure the directions they leave free (siteline.register.icp)
SAMPLE_STABLE, SAMPLE_STRUCTURE = 1, 2


@dataclass(frozen=True)
class LasScan:
    """What one pass over a LAS/LAZ file found. path: the file (relative to its mission once
    ingested). Bounds are site-local metres (float64). class_histogram: points per site class name;
    unknown_codes: points per file code the taxonomy lacks; code_histogram: points per file code, and
    class_scheme what they look like (siteline.site.taxonomy.detect_scheme). outside_fence: points made ``ignore`` by
    the fence. z_unit: the unit of the file's z and its source (siteline.site.crs.ZUnit). colour_stats:
    what the colour and intensity hold (None: scanned before it was recorded). gps_time_standard:
    whether the header's global encoding says GPS times are adjusted standard GPS time (absolute:
    seconds since the GPS epoch less 1e9) rather than seconds of the GPS week. footprint: the
    outline of the points (a fence ring, site-local metres; siteline.site.fence.footprint), or None.
    generating_software: the header's system identifier and generating software, "; "-joined ("siteline
    synth; ..." for a generated site; None when blank or scanned before it was recorded).
    stable_sample: (N, 4) float64 the co-registration sample: site-local x, y, z of points of stable
    surfaces (4th column 1: ground, building) and of structure (2: vegetation, unclassified);
    survey_sample: (N, 5) x, y, z (site-local), intensity and site class of every k-th point of the file
    (both never persisted)."""

    path: str
    source_crs: str
    transformed: bool
    point_count: int
    bounds_min: list[float]
    bounds_max: list[float]
    class_histogram: dict[str, int]
    unknown_codes: dict[int, int]
    outside_fence: int
    colour: str
    density_pts_m2: float
    version: str
    point_format: int
    scale: list[float]
    offset: list[float]
    gps_time_range: list[float] | None
    z_unit: ZUnit | None
    creation_date: str | None
    colour_stats: ColourStats | None = None
    gps_time_standard: bool | None = None
    footprint: list[list[float]] | None = None
    code_histogram: dict[int, int] = field(default_factory=dict)
    class_scheme: str | None = None
    generating_software: str | None = None
    stable_sample: np.ndarray | None = field(default=None, repr=False, compare=False)
    survey_sample: np.ndarray | None = field(default=None, repr=False, compare=False)

    def content_seed(self) -> int:
        """A seed that depends on the cloud's content only (point count, GPS times, classes, bounds in
        whole millimetres of the site frame): the same mission gives the same level-of-detail draw and
        node order whatever its scene id, arrival order or the origin's magnitude.

        The bounds are site-local floats whose last bits depend on the origin (a bound of -65.005 m is
        -65.00500000000011 at one origin and -65.00499999988824 at another), so they are snapped to
        the nearest millimetre, the tile quantum that holds the points themselves: rounding to the
        centimetre put such a bound on either side of a half and changed the whole draw."""
        doc = {
            "points": self.point_count,
            "gps": [round(v, 6) for v in self.gps_time_range] if self.gps_time_range else None,
            "classes": dict(sorted(self.class_histogram.items())),
            "bounds_mm": [int(np.rint(v * 1000.0)) for v in (*self.bounds_min, *self.bounds_max)],
        }
        digest = hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).digest()
        return int.from_bytes(digest[:4], "big")

    def at(self, path: str) -> LasScan:
        """This scan with ``path`` recorded instead (the file's path inside its mission)."""
        return replace(self, path=path)

    def to_dict(self) -> dict[str, JSON]:
        """The JSON form (the samples are left out)."""
        doc = {f.name: getattr(self, f.name) for f in fields(self) if f.name not in _SAMPLES}
        doc["unknown_codes"] = {str(k): v for k, v in self.unknown_codes.items()}
        doc["code_histogram"] = {str(k): v for k, v in self.code_histogram.items()}
        doc["colour_stats"] = self.colour_stats.to_dict() if self.colour_stats else None
        doc["z_unit"] = self.z_unit.to_dict() if self.z_unit is not None else None
        return doc

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON]) -> LasScan:
        """From :meth:`to_dict`'s form (a scan recorded before a field existed lacks it)."""

        def numbers(key: str) -> list[float]:
            return json_numbers(doc[key], key)

        def codes(key: str) -> dict[int, int]:
            return {int(k): json_int(v, key) for k, v in json_object(doc.get(key, {}), key).items()}

        def text(key: str) -> str | None:
            return json_or_none(json_str, doc.get(key), key)

        stats = json_or_none(json_object, doc.get("colour_stats"), "colour_stats")
        z_unit = json_or_none(json_object, doc.get("z_unit"), "z_unit")
        gps = doc.get("gps_time_range")
        footprint = doc.get("footprint")
        return cls(
            path=json_str(doc["path"], "path"), source_crs=json_str(doc["source_crs"], "source_crs"),
            transformed=json_bool(doc["transformed"], "transformed"), point_count=json_int(doc["point_count"], "point_count"),
            bounds_min=numbers("bounds_min"), bounds_max=numbers("bounds_max"),
            class_histogram={k: json_int(v, "class_histogram") for k, v in json_object(doc["class_histogram"], "class_histogram").items()},
            unknown_codes=codes("unknown_codes"), outside_fence=json_int(doc["outside_fence"], "outside_fence"),
            colour=json_str(doc["colour"], "colour"), density_pts_m2=json_number(doc["density_pts_m2"], "density_pts_m2"),
            version=json_str(doc["version"], "version"), point_format=json_int(doc["point_format"], "point_format"),
            scale=numbers("scale"), offset=numbers("offset"),
            gps_time_range=None if gps is None else numbers("gps_time_range"),
            z_unit=ZUnit.from_dict(z_unit) if z_unit else None, creation_date=text("creation_date"),
            colour_stats=ColourStats.from_dict(stats) if stats else None,
            gps_time_standard=json_or_none(json_bool, doc.get("gps_time_standard"), "gps_time_standard"),
            footprint=None if footprint is None else [json_numbers(p, "footprint") for p in json_list(footprint, "footprint")],
            code_histogram=codes("code_histogram"), class_scheme=text("class_scheme"),
            generating_software=text("generating_software"),
        )  # fmt: skip


_SAMPLES = frozenset({"stable_sample", "survey_sample"})
