"""The site specification: the persisted, validated description of one construction site."""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NotRequired, TypedDict

import pyproj

from siteline.errors import SiteError
from siteline.schema import validated
from siteline.site.crs import crs_text, parse_crs, parse_origin
from siteline.site.fence import validate_fence
from siteline.site.taxonomy import Taxonomy, TaxonomyDoc, default_taxonomy

NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")  # used with fullmatch: no trailing newline
DEFAULT_TILE_SIZE_M = 50.0


class SiteDoc(TypedDict):
    """A site config (``schema/site.schema.json``): name, CRS, origin (CRS units), fence (site-local
    metres, closed ring; None: none), taxonomy and tile size (metres)."""

    name: str
    crs: str
    origin: list[float]
    fence: NotRequired[list[list[float]] | None]
    taxonomy: TaxonomyDoc
    tile_size_m: float


@dataclass(frozen=True)
class SiteSpec:
    """One site.

    crs: canonical CRS text (``EPSG:nnnn`` or WKT2). origin: float64 (x, y, z) in that CRS.
    fence: ring of (x, y) site-local metres without the closing vertex, or None.
    tile_size_m: edge of the square tile grid in site-local metres, anchored at the site origin.
    version: the version of its taxonomy and fence (1 at creation; each `site update --taxonomy/--fence`
    adds one); the catalog's, not part of the site's JSON.
    """

    name: str
    crs: str
    origin: tuple[float, float, float]
    fence: tuple[tuple[float, float], ...] | None
    taxonomy: Taxonomy
    tile_size_m: float = DEFAULT_TILE_SIZE_M
    version: int = 1

    @property
    def pyproj_crs(self) -> pyproj.CRS:
        return parse_crs(self.crs)

    def to_dict(self) -> SiteDoc:
        fence = None
        if self.fence is not None:
            fence = [list(v) for v in self.fence] + [list(self.fence[0])]
        return {
            "name": self.name,
            "crs": self.crs,
            "origin": list(self.origin),
            "fence": fence,
            "taxonomy": self.taxonomy.to_dict(),
            "tile_size_m": self.tile_size_m,
        }

    @classmethod
    def from_dict(cls, raw: object, source: str = "site config") -> SiteSpec:
        doc = validated(raw, "site.schema.json", source, SiteDoc)
        return make_site_spec(
            doc["name"],
            doc["crs"],
            doc["origin"],
            doc.get("fence"),
            Taxonomy.from_dict(doc["taxonomy"], source=f"{source} taxonomy"),
            doc["tile_size_m"],
        )


def make_site_spec(
    name: str,
    crs: str,
    origin: Sequence[float],
    fence_m: Sequence[Sequence[float]] | None = None,
    taxonomy: Taxonomy | None = None,
    tile_size_m: float = DEFAULT_TILE_SIZE_M,
) -> SiteSpec:
    """Validate every field of a site and return its spec; raises a :class:`SitelineError` leaf.

    fence_m: closed ring (last vertex repeats the first) in site-local metres, or None.
    """
    if not isinstance(name, str) or not NAME_PATTERN.fullmatch(name):
        raise SiteError(
            f"site name {name!r} is not allowed: use 1-64 letters, digits, '_', '.', '-', starting with a letter or digit."
        )
    xyz = parse_origin(origin)
    canonical = crs_text(parse_crs(crs, near=(xyz[0], xyz[1])))
    ring = tuple(validate_fence(fence_m, source=f"site {name} fence")) if fence_m is not None else None
    if not (isinstance(tile_size_m, int | float) and 0.5 <= float(tile_size_m) <= 10_000.0):
        raise SiteError(f"site {name}: tile size {tile_size_m!r} m is outside 0.5-10000 m.")
    return SiteSpec(name, canonical, xyz, ring, taxonomy or default_taxonomy(), float(tile_size_m))
