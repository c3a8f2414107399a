"""The LAS scan: what ingest's one pass over a mission's point cloud found."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

# how a scan names a file's colour, and whether it is 0-255 in 16-bit fields
COLOUR_NAMES = {True: "rgb 8-bit stored in 16-bit fields", False: "rgb 16-bit"}
EIGHT_BIT = {name: eight for eight, name in COLOUR_NAMES.items()}


@dataclass(frozen=True)
class LasScan:
    """What one pass over a LAS/LAZ file found. path: the file (relative to its mission once
    ingested). Bounds are site-local metres (float64). class_histogram: points per site class name;
    unknown_codes: points per file code the taxonomy lacks. outside_fence: points made ``ignore`` by
    the fence. z_unit: the unit of the file's z and its source (siteline.crs.ZUnit). stable_sample:
    (N, 3) float64 site-local points of stable classes for the alignment check (never persisted)."""

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
    z_unit: dict[str, Any]
    creation_date: str | None
    stable_sample: np.ndarray | None = field(default=None, repr=False, compare=False)

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

    def to_dict(self) -> dict[str, Any]:
        """The JSON form (the stable sample is left out)."""
        doc = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "stable_sample"}
        doc["unknown_codes"] = {str(k): v for k, v in self.unknown_codes.items()}
        return doc

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> LasScan:
        names = {f.name for f in fields(cls)} - {"stable_sample"}
        values = {k: v for k, v in doc.items() if k in names}
        values["unknown_codes"] = {int(k): int(v) for k, v in doc.get("unknown_codes", {}).items()}
        return cls(**values)
