"""Coordinate reference systems and the site-local frame (DESIGN.md §2).

Georeferenced coordinates are float64 in the site CRS; site-local = georeferenced - site origin
(float64 subtraction, axes unchanged).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pyproj
from pyproj.exceptions import CRSError as PyprojCRSError

from siteline.errors import CRSError, GeometryError
from siteline.schema import JSON, json_float

# A site origin further than this from the CRS' own origin is almost certainly a unit or axis mistake.
MAX_ABS_COORDINATE_M = 1.0e8


def crs_label(text: str, crs: pyproj.CRS | None = None) -> str:
    """``text`` as a message names a CRS: itself when short (``EPSG:2994``), else the CRS's name (a
    WKT or PROJ JSON is hundreds of characters)."""
    text = text.strip()
    if len(text) <= 40:
        return repr(text)
    return f"{crs.name!r} (given as WKT)" if crs is not None else f"{text[:40]!r}..."


def parse_crs(text: str, near: tuple[float, float] | None = None) -> pyproj.CRS:
    """The CRS named by ``text`` (``EPSG:32618``, WKT, PROJ JSON); :class:`CRSError` if unusable.
    ``near``: a point (x, y) in that CRS (the site origin) that names the UTM zone to suggest."""
    if not isinstance(text, str) or not text.strip():
        raise CRSError("CRS is empty: give an EPSG code such as EPSG:32618, or a WKT string.")
    try:
        crs = pyproj.CRS.from_user_input(text.strip())
    except PyprojCRSError as exc:
        raise CRSError(f"CRS {crs_label(text)} is not known to PROJ: {exc}. Give e.g. EPSG:32618.") from exc
    label = crs_label(text, crs)
    if crs.is_geographic:
        raise CRSError(
            f"CRS {label} ({crs.name}) is geographic (degrees); siteline needs a projected CRS in metres, "
            f"e.g. {metric_alternative(crs, near)}."
        )
    if not crs.is_projected and not crs.is_engineering and not crs.is_compound:
        raise CRSError(f"CRS {label} ({crs.name}) is not a projected CRS.")
    unit = crs.axis_info[0].unit_name if crs.axis_info else "metre"
    if unit not in ("metre", "meter", "m"):
        raise CRSError(
            f"site CRS {label} has horizontal unit {unit!r}; a site's frame is in metres "
            f"(radii, spacings and tile sizes are metres). Create the site in a metric CRS such as "
            f"{metric_alternative(crs, near)}; missions in this CRS are then converted at ingest, "
            "z included (`siteline ingest --crs`, `--z-unit`)."
        )
    return crs


def metric_alternative(crs: pyproj.CRS, near: tuple[float, float] | None = None) -> str:
    """A metric CRS (``EPSG:nnnn (name)``): the UTM zone, in ``crs``'s datum or WGS 84, of the point
    ``near`` (x, y in ``crs``: the data's or the site's centre) or else of the centre of ``crs``'s
    area of use."""
    from pyproj.aoi import AreaOfInterest
    from pyproj.database import query_utm_crs_info

    area = crs.area_of_use
    lonlat = None
    if near is not None and crs.geodetic_crs is not None:
        try:
            to_geo = pyproj.Transformer.from_crs(crs, crs.geodetic_crs.to_2d(), always_xy=True)
            lon, lat = to_geo.transform(float(near[0]), float(near[1]))
            if math.isfinite(lon) and math.isfinite(lat) and abs(lat) <= 84.0:
                lonlat = (lon, lat)
        except PyprojCRSError:
            lonlat = None
    if lonlat is None and area is None:
        return "the UTM zone of the site (EPSG:326xx north, EPSG:327xx south)"
    lon, lat = lonlat or ((area.west + area.east) / 2.0, (area.south + area.north) / 2.0)  # type: ignore[union-attr]
    aoi = AreaOfInterest(lon, lat, lon, lat)
    geodetic = crs.geodetic_crs
    datum = geodetic.datum.name if geodetic is not None and geodetic.datum is not None else ""
    for name in ("NAD83" if datum.startswith("NAD83") else datum, "WGS 84"):
        found = [i for i in query_utm_crs_info(datum_name=name, area_of_interest=aoi) if not i.deprecated]
        if found:
            return f"{found[0].auth_name}:{found[0].code} ({found[0].name})"
    return "the UTM zone of the site (EPSG:326xx north, EPSG:327xx south)"


def parse_source_crs(text: str) -> pyproj.CRS:
    """The CRS of a mission's data (``--crs``): any CRS PROJ knows, projected in any unit, geographic
    or compound; ingest transforms it into the site CRS (:func:`to_site_transform`)."""
    if not isinstance(text, str) or not text.strip():
        raise CRSError("CRS is empty: give an EPSG code such as EPSG:2994, or a WKT string.")
    try:
        return pyproj.CRS.from_user_input(text.strip())
    except PyprojCRSError as exc:
        raise CRSError(f"CRS {text!r} is not known to PROJ: {exc}. Give e.g. EPSG:32618.") from exc


# metres per unit of the vertical units ``--z-unit`` accepts
Z_UNITS_M = {
    "m": ("metre", 1.0),
    "metre": ("metre", 1.0),
    "ft": ("foot", 0.3048),
    "foot": ("foot", 0.3048),
    "ftus": ("US survey foot", 1200.0 / 3937.0),
    "us-ft": ("US survey foot", 1200.0 / 3937.0),
    "us survey foot": ("US survey foot", 1200.0 / 3937.0),
}


@dataclass(frozen=True)
class ZUnit:
    """The unit of a mission's z values: ``name``, ``metres`` per unit, and ``source`` (where the
    choice came from: ``vertical CRS``, ``horizontal unit``, ``--z-unit``), recorded in the scene."""

    name: str
    metres: float
    source: str

    def to_dict(self) -> dict[str, JSON]:
        return {"name": self.name, "metres": self.metres, "source": self.source}

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON]) -> ZUnit:
        return cls(str(doc["name"]), json_float(doc["metres"], "metres"), str(doc["source"]))


def parse_z_unit(text: str) -> ZUnit:
    """``--z-unit``: m, ft or ftUS (also metre, foot, us-ft)."""
    key = str(text).strip().lower()
    if key not in Z_UNITS_M:
        raise CRSError(
            f"--z-unit {text!r} is not known: use m, ft (international foot) or ftUS (US survey foot)."
        )
    name, metres = Z_UNITS_M[key]
    return ZUnit(name, metres, "--z-unit")


def z_unit_of(src: pyproj.CRS, override: ZUnit | None = None) -> ZUnit:
    """The unit of z in data of CRS ``src``: ``override`` when given, else the unit of ``src``'s
    vertical CRS (compound or 3D), else its horizontal unit (a LAS in a feet CRS with no vertical CRS
    holds feet in z too, as autzen.laz does); degrees of a geographic CRS mean metres of height."""
    if override is not None:
        return override
    vertical = [c for c in src.sub_crs_list if c.is_vertical] if src.is_compound else []
    if vertical and vertical[0].axis_info:
        ax = vertical[0].axis_info[0]
        return ZUnit(ax.unit_name, float(ax.unit_conversion_factor), "vertical CRS")
    if len(src.axis_info) >= 3:
        ax = src.axis_info[2]
        return ZUnit(ax.unit_name, float(ax.unit_conversion_factor), "vertical CRS")
    if src.is_geographic or not src.axis_info:
        return ZUnit("metre", 1.0, "horizontal unit")
    ax = src.axis_info[0]
    return ZUnit(ax.unit_name, float(ax.unit_conversion_factor), "horizontal unit")


class ToSiteCRS:
    """Float64 transformation of (N, 3) points from a source CRS into the site CRS, z in metres.

    x, y go through PROJ from the source's horizontal CRS to the site's; z is multiplied by the
    source's :class:`ZUnit` (PROJ leaves z untouched between CRSs without a vertical component). When
    both CRSs are compound and no ``--z-unit`` is given, PROJ's full 3D transformation does it all.
    """

    def __init__(self, src: pyproj.CRS, dst: pyproj.CRS, z_unit: ZUnit) -> None:
        self.src, self.dst, self.z_unit = src, dst, z_unit
        self.full_3d = src.is_compound and dst.is_compound and z_unit.source != "--z-unit"
        horizontal = _horizontal(src)
        self._tr: pyproj.Transformer | None
        if self.full_3d:
            self._tr = transformer(src, dst)
        elif horizontal.equals(_horizontal(dst), ignore_axis_order=True):
            self._tr = None
        else:
            self._tr = transformer(horizontal, _horizontal(dst))

    @property
    def is_identity(self) -> bool:
        return self._tr is None and self.z_unit.metres == 1.0

    def __call__(self, xyz: np.ndarray) -> np.ndarray:
        xyz = np.asarray(xyz, dtype=np.float64)
        if self.full_3d and self._tr is not None:
            x, y, z = self._tr.transform(xyz[:, 0], xyz[:, 1], xyz[:, 2], errcheck=False)
            return np.stack([np.asarray(x), np.asarray(y), np.asarray(z)], axis=1)
        if self._tr is None:
            x, y = xyz[:, 0], xyz[:, 1]
        else:
            x, y = self._tr.transform(xyz[:, 0], xyz[:, 1], errcheck=False)
        z = xyz[:, 2] * self.z_unit.metres if self.z_unit.metres != 1.0 else xyz[:, 2]
        return np.stack([np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64), z], axis=1)

    def probe(self, xy_site: Sequence[float]) -> np.ndarray:
        """The source (x, y) of a site-CRS position (checks that an inverse exists)."""
        if self._tr is None:
            return np.asarray(xy_site[:2], dtype=np.float64)
        return np.asarray(self._tr.transform(xy_site[0], xy_site[1], errcheck=True, direction="INVERSE")[:2])


def _horizontal(crs: pyproj.CRS) -> pyproj.CRS:
    """The horizontal part of a compound CRS (the CRS itself otherwise)."""
    if crs.is_compound:
        for sub in crs.sub_crs_list:
            if not sub.is_vertical:
                return sub
    return crs


def crs_text(crs: pyproj.CRS) -> str:
    """Canonical text for storage: ``EPSG:nnnn`` when PROJ knows the code exactly, WKT2 otherwise."""
    code = crs.to_epsg(min_confidence=100)
    if code is not None:
        return f"EPSG:{code}"
    return crs.to_wkt()


def parse_origin(values: Sequence[float]) -> tuple[float, float, float]:
    """A site origin (x, y, z) in CRS units, float64, finite and not absurd."""
    if len(values) != 3:
        raise GeometryError(f"site origin needs 3 numbers (X Y Z), got {len(values)}.")
    out = []
    for axis, v in zip("XYZ", values, strict=True):
        try:
            f = float(v)
        except (TypeError, ValueError) as exc:
            raise GeometryError(f"site origin {axis}={v!r} is not a number.") from exc
        if not math.isfinite(f):
            raise GeometryError(
                f"site origin {axis}={v!r} is not finite: give a real coordinate in the site CRS."
            )
        if abs(f) > MAX_ABS_COORDINATE_M:
            raise GeometryError(
                f"site origin {axis}={f} is beyond {MAX_ABS_COORDINATE_M:g} m: check units and axes."
            )
        out.append(f)
    return out[0], out[1], out[2]


def site_from_crs(xyz_crs: np.ndarray, origin: Sequence[float]) -> np.ndarray:
    """Site-local float64 coordinates of georeferenced points.

    xyz_crs: (N, 3) float64 in the site CRS. origin: (3,) float64 site origin. Returns (N, 3) float64.
    """
    xyz = np.asarray(xyz_crs)
    if xyz.dtype != np.float64:
        raise GeometryError(
            f"georeferenced coordinates must be float64, got {xyz.dtype} (float32 loses metres)."
        )
    return xyz - np.asarray(origin, dtype=np.float64)


def crs_from_site(xyz_site: np.ndarray, origin: Sequence[float]) -> np.ndarray:
    """Georeferenced float64 coordinates of site-local points. xyz_site: (N, 3) any float dtype."""
    return np.asarray(xyz_site, dtype=np.float64) + np.asarray(origin, dtype=np.float64)


def transformer(src: pyproj.CRS, dst: pyproj.CRS) -> pyproj.Transformer:
    """An always-xy transformer from ``src`` to ``dst``; :class:`CRSError` when PROJ has none."""
    try:
        return pyproj.Transformer.from_crs(src, dst, always_xy=True)
    except PyprojCRSError as exc:
        raise CRSError(f"no transformation from {src.name} to {dst.name}: {exc}") from exc


def transform_points(xyz: np.ndarray, src: pyproj.CRS, dst: pyproj.CRS) -> np.ndarray:
    """(N, 3) float64 points from ``src`` to ``dst`` in float64; raises if any result is not finite."""
    if src == dst:
        return np.asarray(xyz, dtype=np.float64)
    t = transformer(src, dst)
    x, y, z = t.transform(xyz[:, 0], xyz[:, 1], xyz[:, 2], errcheck=False)
    out = np.stack([np.asarray(x), np.asarray(y), np.asarray(z)], axis=1).astype(np.float64)
    if not np.isfinite(out).all():
        raise CRSError(
            f"transforming points from {src.name} to {dst.name} gave non-finite values (outside the CRS area?)."
        )
    return out
