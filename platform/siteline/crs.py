"""Coordinate reference systems and the site-local frame (DESIGN.md §2).

Georeferenced coordinates are float64 in the site CRS; site-local = georeferenced - site origin
(float64 subtraction, axes unchanged).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pyproj
from pyproj.exceptions import CRSError as PyprojCRSError

from siteline.errors import CRSError, GeometryError

# A site origin further than this from the CRS' own origin is almost certainly a unit or axis mistake.
MAX_ABS_COORDINATE_M = 1.0e8


def parse_crs(text: str) -> pyproj.CRS:
    """The CRS named by ``text`` (``EPSG:32618``, WKT, PROJ JSON); :class:`CRSError` if unusable."""
    if not isinstance(text, str) or not text.strip():
        raise CRSError("CRS is empty: give an EPSG code such as EPSG:32618, or a WKT string.")
    try:
        crs = pyproj.CRS.from_user_input(text.strip())
    except PyprojCRSError as exc:
        raise CRSError(f"CRS {text!r} is not known to PROJ: {exc}. Give e.g. EPSG:32618.") from exc
    if crs.is_geographic:
        raise CRSError(
            f"CRS {text!r} ({crs.name}) is geographic (degrees); siteline needs a projected CRS in metres, "
            "e.g. the UTM zone of the site (EPSG:326xx)."
        )
    if not crs.is_projected and not crs.is_engineering and not crs.is_compound:
        raise CRSError(f"CRS {text!r} ({crs.name}) is not a projected CRS.")
    unit = crs.axis_info[0].unit_name if crs.axis_info else "metre"
    if unit not in ("metre", "meter", "m"):
        raise CRSError(f"CRS {text!r} ({crs.name}) has horizontal unit {unit!r}; siteline needs metres.")
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
