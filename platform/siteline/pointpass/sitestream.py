"""The one LAS/LAZ -> site frame stream (DESIGN.md §2): a file's CRS, the float64 transformation into
the site CRS (z in metres), subtraction of the site origin, refusal of non-finite or absurd
coordinates, taxonomy mapping and the fence. Ingest's scan and the tile writer both read through it."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import laspy
import numpy as np
import pyproj

from siteline.camera.poses import Rigid
from siteline.errors import CRSError, PointCloudError
from siteline.pointpass.kernels import cut
from siteline.pointpass.lasio import DEFAULT_CHUNK_POINTS, MAX_SITE_LOCAL_M, PointChunk, iter_chunks, open_las
from siteline.site.crs import ToSiteCRS, ZUnit, parse_source_crs, z_unit_of
from siteline.site.fence import inside_fence
from siteline.site.spec import SiteSpec
from siteline.tolerances import LENGTH_TOL_M


@dataclass
class SiteChunk:
    """A chunk in the site frame: local (N, 3) float64 site-local metres, the raw chunk, site classes
    (N,) uint8 after the taxonomy and the fence, which raw codes the taxonomy knows, which points lie
    outside the fence, and the (3,) lowest and highest site-local coordinates."""

    local: np.ndarray
    chunk: PointChunk
    classes: np.ndarray
    known_code: np.ndarray
    outside: np.ndarray
    lo: np.ndarray
    hi: np.ndarray


# a rigid correction of site-local coordinates, (4, 4) row-major as nested tuples (picklable, JSON-able)
Correction = tuple[tuple[float, ...], ...]


def correction_rigid(correction: Correction | list[list[float]]) -> Rigid:
    """A correction (4 x 4) as the pose it is: the previous scene's site-local frame from this one's."""
    m = np.asarray(correction, dtype=np.float64)
    return Rigid("prev", "new", m[:3, :3], m[:3, 3])


def file_crs(reader: laspy.LasReader, path: Path) -> pyproj.CRS | None:
    """The CRS of a LAS header (WKT or GeoTIFF keys), None when it has none."""
    try:
        return reader.header.parse_crs()
    except Exception as exc:  # laspy/pyproj raise many types on malformed records
        raise CRSError(f"point cloud {path}: its CRS record cannot be parsed ({exc}); pass --crs.") from exc


def wrong_header_crs(crs: pyproj.CRS, mins: Sequence[float], maxs: Sequence[float]) -> str | None:
    """Why a header's CRS cannot be the CRS its coordinates are in (None when it may be): degrees
    beyond +-180 / +-90, or coordinates more than 1,000 km outside a projected CRS's area of use."""
    lo, hi = np.asarray(mins, dtype=np.float64)[:2], np.asarray(maxs, dtype=np.float64)[:2]
    if crs.is_geographic:
        if max(abs(lo[0]), abs(hi[0])) > 180.0 or max(abs(lo[1]), abs(hi[1])) > 90.0:
            return f"{crs.name} is in degrees, but x reaches {max(abs(lo[0]), abs(hi[0])):,.0f} and y {max(abs(lo[1]), abs(hi[1])):,.0f}"
        return None
    area = crs.area_of_use
    if area is None or not crs.is_projected:
        return None
    try:
        x0, y0, x1, y1 = pyproj.Transformer.from_crs("EPSG:4326", crs, always_xy=True).transform_bounds(
            *area.bounds
        )
    except Exception:  # an area PROJ cannot project: no judgement
        return None
    unit = crs.axis_info[0].unit_conversion_factor if crs.axis_info else 1.0
    margin = 1.0e6 / unit
    if not all(np.isfinite([x0, y0, x1, y1])):
        return None
    if hi[0] < x0 - margin or lo[0] > x1 + margin or hi[1] < y0 - margin or lo[1] > y1 + margin:
        return f"its coordinates ({lo[0]:,.0f}, {lo[1]:,.0f}) lie more than 1,000 km outside {crs.name}'s area of use"
    return None


def source_crs(path: Path, crs_override: str | None, reader: laspy.LasReader | None = None) -> pyproj.CRS:
    """The CRS of a point cloud: its own record, or ``crs_override`` when it has none or when the
    record is provably wrong (:func:`wrong_header_crs`). ``reader``: the file already opened."""
    if reader is not None:
        in_file, mins, maxs = file_crs(reader, path), reader.header.mins, reader.header.maxs
    else:
        with open_las(path) as opened:
            in_file, mins, maxs = file_crs(opened, path), opened.header.mins, opened.header.maxs
    if in_file is None and crs_override is None:
        raise CRSError(f"point cloud {path} has no CRS record; pass --crs (e.g. --crs EPSG:32618).")
    wrong = wrong_header_crs(in_file, mins, maxs) if in_file is not None else None
    if wrong is not None:
        if crs_override is None:
            raise CRSError(
                f"point cloud {path}: its header's CRS cannot be right ({wrong}); pass --crs with the CRS its "
                "coordinates are in (it overrides a header that is provably wrong)."
            )
        in_file = None
    if (
        in_file is not None
        and crs_override is not None
        and not in_file.equals(parse_source_crs(crs_override), ignore_axis_order=True)
    ):
        raise CRSError(
            f"point cloud {path} declares {in_file.name} but --crs says {crs_override}: remove --crs or fix the file."
        )
    src = in_file if in_file is not None else parse_source_crs(str(crs_override))
    if not (src.is_projected or src.is_compound or src.is_geographic):
        raise CRSError(
            f"point cloud {path}: CRS {src.name} is neither projected nor geographic; it cannot be "
            "transformed to the site CRS."
        )
    return src


def source_transformer(
    path: Path, site: SiteSpec, src: pyproj.CRS, z_unit: ZUnit | None = None
) -> ToSiteCRS | None:
    """A float64 transformation from the file's CRS (z in ``z_unit``, else the unit
    :func:`siteline.site.crs.z_unit_of` finds) to the site's, None when there is nothing to do."""
    dst = site.pyproj_crs
    unit = z_unit_of(src, z_unit)
    try:
        tr = ToSiteCRS(src, dst, unit)
        probe = tr.probe(site.origin[:2])
    except Exception as exc:
        raise CRSError(
            f"point cloud {path}: no usable transformation from {src.name} to the site CRS "
            f"{dst.name} ({exc})."
        ) from exc
    if not np.isfinite(probe).all():
        raise CRSError(f"point cloud {path}: {src.name} cannot be transformed to the site CRS {dst.name}.")
    return None if tr.is_identity else tr


@dataclass(frozen=True)
class SiteReading:
    """How :func:`site_chunks` reads a file beyond the file and the site. ``start``/``stop``,
    ``chunk_points``, ``eight_bit``: as :func:`siteline.pointpass.lasio.iter_chunks`. ``correction``:
    a rigid transform (4 x 4, site-local metres) applied after the origin is subtracted: the
    co-registration of a later scene onto the earlier one (siteline.register), so every reader sees
    the corrected geometry. ``class_lut``: (256,) uint8 site class id per file code and (256,) bool of
    the codes it maps; None: the taxonomy's LAS source codes. ``fence_tol_m``: how far outside the
    fence still counts as inside (a label import reads coordinates rounded to the tile quantum, so it
    takes that quantum: a point ingest found inside stays inside)."""

    start: int = 0
    stop: int | None = None
    chunk_points: int = DEFAULT_CHUNK_POINTS
    eight_bit: bool | None = None
    correction: Correction | None = None
    class_lut: tuple[np.ndarray, np.ndarray] | None = None
    fence_tol_m: float = LENGTH_TOL_M


def local_chunks(
    path: Path,
    origin: Sequence[float],
    tr: ToSiteCRS | None,
    how: SiteReading = SiteReading(),
    reader: laspy.LasReader | None = None,
) -> Iterator[tuple[np.ndarray, PointChunk, np.ndarray, np.ndarray]]:
    """The one way a LAS/LAZ file becomes site-local: per chunk, the float64 transform to the site CRS
    (``tr``; None: the file is in it), the origin subtracted, the co-registration applied, and
    non-finite or absurd coordinates (over ``MAX_SITE_LOCAL_M`` from the origin) refused naming the
    file. Yields (site-local (N, 3) float64 metres, the chunk, its low and high corner)."""
    o = np.asarray(origin, dtype=np.float64)
    corrected = None if how.correction is None else correction_rigid(how.correction)
    for chunk in iter_chunks(
        path, how.chunk_points, how.eight_bit, reader=reader, start=how.start, stop=how.stop
    ):
        xyz = chunk.xyz_crs
        if tr is not None:
            xyz = tr(xyz)
        local = xyz - o
        if corrected is not None:
            local = corrected.apply(local)
        lo, hi, bad = cut.bounds(local)
        if bad:
            raise PointCloudError(
                f"point cloud {path}: {bad} points have non-finite coordinates (NaN or inf)."
            )
        far = float(np.abs(np.r_[lo, hi]).max(initial=0.0)) if len(local) else 0.0
        if far > MAX_SITE_LOCAL_M:
            raise PointCloudError(
                f"point cloud {path}: points lie {far:,.0f} m from the site origin {tuple(o.tolist())} (limit "
                f"{MAX_SITE_LOCAL_M:,.0f} m): wrong site or origin (--origin), wrong CRS or corrupt coordinates."
            )
        yield local, chunk, lo, hi


def site_chunks(
    path: Path,
    site: SiteSpec,
    tr: ToSiteCRS | None,
    how: SiteReading = SiteReading(),
    reader: laspy.LasReader | None = None,
) -> Iterator[SiteChunk]:
    """Stream a LAS/LAZ file into the site frame (:func:`local_chunks`), with the taxonomy mapping and
    points outside the fence made ignore; ``how``: :class:`SiteReading`. ``reader``: the file already
    opened."""
    class_lut, fence_tol_m = how.class_lut, how.fence_tol_m
    tax = site.taxonomy
    lut, known = class_lut if class_lut is not None else tax.code_lut("las")
    for local, chunk, lo, hi in local_chunks(path, site.origin, tr, how, reader):
        codes = chunk.classification
        cls = lut[codes]
        outside = np.zeros(len(cls), dtype=bool)
        if site.fence is not None:
            outside = ~inside_fence(
                local[:, :2], site.fence, tol_m=fence_tol_m, box=(lo[0], lo[1], hi[0], hi[1])
            )
            cls = np.where(outside, tax.ignore_id, cls)
        yield SiteChunk(local, chunk, cls.astype(np.uint8), known[codes], outside, lo, hi)


@dataclass(frozen=True)
class SiteLocalCloud:
    """A whole (small) cloud in the site-local frame. xyz: (N, 3) float32 metres; rgb (N, 3) uint8 or
    None; classification (N,) uint8 source codes."""

    xyz: np.ndarray
    rgb: np.ndarray | None
    classification: np.ndarray


def read_site_local(path: Path, origin: Sequence[float]) -> SiteLocalCloud:
    """Read a LAS/LAZ file whole into site-local float32 (for renders and tools on small clouds) by
    :func:`local_chunks`, its coordinates taken in the site CRS."""
    xyzs, rgbs, classes = [], [], []
    for local, chunk, _, _ in local_chunks(path, origin, None):
        xyzs.append(local.astype(np.float32))
        classes.append(chunk.classification)
        if chunk.rgb is not None:
            rgbs.append(chunk.rgb)
    xyz = np.concatenate(xyzs) if xyzs else np.zeros((0, 3), np.float32)
    cls = np.concatenate(classes) if classes else np.zeros(0, np.uint8)
    rgb = np.concatenate(rgbs) if rgbs else None
    return SiteLocalCloud(xyz=xyz, rgb=rgb, classification=cls)
