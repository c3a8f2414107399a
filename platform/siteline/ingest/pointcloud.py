"""Streaming a mission's LAS/LAZ into the site frame, and the one validating pass of ingest: CRS,
transformation to the site CRS, statistics, and a sample of stable-class points for the alignment
check."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import laspy
import numpy as np
import pyproj

from siteline.crs import ToSiteCRS, ZUnit, crs_text, parse_source_crs, z_unit_of
from siteline.errors import CRSError, PointCloudError
from siteline.fence import inside_fence
from siteline.lasio import DEFAULT_CHUNK_POINTS, MAX_SITE_LOCAL_M, PointChunk, iter_chunks, open_las
from siteline.site import SiteSpec

STABLE_CLASSES = ("ground", "building")


@dataclass
class SiteChunk:
    """A chunk in the site frame: local (N, 3) float64 site-local metres, the raw chunk, site classes
    (N,) uint8 after the taxonomy and the fence, which raw codes the taxonomy knows, which points lie
    outside the fence."""

    local: np.ndarray
    chunk: PointChunk
    classes: np.ndarray
    known_code: np.ndarray
    outside: np.ndarray


@dataclass
class LasScan:
    """What one pass over a LAS/LAZ file found. Bounds are site-local metres (float64)."""

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
    z_unit: dict
    stable_sample: np.ndarray = field(repr=False)

    def to_dict(self) -> dict:
        d = {k: v for k, v in self.__dict__.items() if k != "stable_sample"}
        d["unknown_codes"] = {str(k): v for k, v in self.unknown_codes.items()}
        return d


def file_crs(reader: laspy.LasReader, path: Path) -> pyproj.CRS | None:
    """The CRS of a LAS header (WKT or GeoTIFF keys), None when it has none."""
    try:
        return reader.header.parse_crs()
    except Exception as exc:  # laspy/pyproj raise many types on malformed records
        raise CRSError(f"point cloud {path}: its CRS record cannot be parsed ({exc}); pass --crs.") from exc


def source_crs(path: Path, crs_override: str | None) -> pyproj.CRS:
    """The CRS of a point cloud: its own record, or ``crs_override`` when it has none."""
    with open_las(path) as reader:
        in_file = file_crs(reader, path)
    if in_file is None and crs_override is None:
        raise CRSError(f"point cloud {path} has no CRS record; pass --crs (e.g. --crs EPSG:32618).")
    if (
        in_file is not None
        and crs_override is not None
        and not in_file.equals(parse_source_crs(crs_override), ignore_axis_order=True)
    ):
        raise CRSError(
            f"point cloud {path} declares {in_file.name} but --crs says {crs_override}: remove --crs or fix the file."
        )
    src = in_file if in_file is not None else parse_source_crs(crs_override)
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
    :func:`siteline.crs.z_unit_of` finds) to the site's, None when there is nothing to do."""
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


def site_chunks(
    path: Path, site: SiteSpec, tr: ToSiteCRS | None, chunk_points: int = DEFAULT_CHUNK_POINTS
) -> Iterator[SiteChunk]:
    """Stream a LAS/LAZ file into the site frame: float64 transform to the site CRS, subtraction of the
    origin, refusal of non-finite or absurd coordinates, taxonomy mapping, fence -> ignore."""
    tax = site.taxonomy
    lut, known = tax.code_lut("las")
    origin = np.asarray(site.origin, dtype=np.float64)
    for chunk in iter_chunks(path, chunk_points):
        xyz = chunk.xyz_crs
        if tr is not None:
            xyz = tr(xyz)
        local = xyz - origin
        if not np.isfinite(local).all():
            bad = int((~np.isfinite(local).all(axis=1)).sum())
            raise PointCloudError(
                f"point cloud {path}: {bad} points have non-finite coordinates (NaN or inf)."
            )
        far = float(np.abs(local).max(initial=0.0))
        if far > MAX_SITE_LOCAL_M:
            raise PointCloudError(
                f"point cloud {path}: points lie {far:,.0f} m from the site origin {tuple(origin)} (limit "
                f"{MAX_SITE_LOCAL_M:,.0f} m): wrong site, wrong CRS or corrupt coordinates."
            )
        codes = chunk.classification
        cls = lut[codes]
        outside = np.zeros(len(cls), dtype=bool)
        if site.fence is not None:
            outside = ~inside_fence(local[:, :2], site.fence)
            cls = np.where(outside, tax.ignore_id, cls)
        yield SiteChunk(local, chunk, cls.astype(np.uint8), known[codes], outside)


def scan_las(
    path: Path,
    site: SiteSpec,
    crs_override: str | None = None,
    *,
    z_unit: ZUnit | None = None,
    sample_max: int = 200_000,
    chunk_points: int = DEFAULT_CHUNK_POINTS,
    progress: Callable[[int], None] | None = None,
    seed: int = 0,
) -> LasScan:
    """Read ``path`` once in chunks: bring coordinates into the site CRS in float64, refuse non-finite
    or absurd ones, map classes through the site taxonomy, and gather statistics. z is converted to
    metres from ``z_unit`` (``--z-unit``) or the unit the file's CRS implies (recorded in the scan)."""
    path = Path(path)
    with open_las(path) as reader:
        header = reader.header
        n_total = int(header.point_count)
        version = f"{header.version.major}.{header.version.minor}"
        pf = int(header.point_format.id)
        scale = [float(v) for v in header.scales]
        offset = [float(v) for v in header.offsets]
    if not (np.isfinite(scale).all() and np.isfinite(offset).all()) or min(abs(s) for s in scale) == 0:
        raise PointCloudError(
            f"point cloud {path}: header scale {scale} / offset {offset} is not finite and non-zero."
        )
    src = source_crs(path, crs_override)
    tr = source_transformer(path, site, src, z_unit)
    stable_ids = np.array([site.taxonomy.id_of(c) for c in STABLE_CLASSES], dtype=np.uint8)
    rng = np.random.default_rng(seed)
    keep_p = min(1.0, sample_max / max(n_total, 1))
    hist = np.zeros(256, np.int64)
    unknown = np.zeros(256, np.int64)
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    count = outside = 0
    tmin, tmax = np.inf, -np.inf
    samples = []
    colour = "none"
    for sc in site_chunks(path, site, tr, chunk_points):
        local, chunk, cls = sc.local, sc.chunk, sc.classes
        unknown += np.bincount(chunk.classification[~sc.known_code], minlength=256)
        outside += int(sc.outside.sum())
        hist += np.bincount(cls, minlength=256)
        lo = np.minimum(lo, local.min(axis=0))
        hi = np.maximum(hi, local.max(axis=0))
        count += len(local)
        if chunk.gps_time is not None and len(chunk.gps_time):
            tmin, tmax = min(tmin, float(chunk.gps_time.min())), max(tmax, float(chunk.gps_time.max()))
        if chunk.rgb is not None:
            colour = "rgb 8-bit stored in 16-bit fields" if chunk.colour_8bit else "rgb 16-bit"
        stable = np.isin(cls, stable_ids) & (rng.random(len(cls)) < keep_p)
        samples.append(local[stable])
        if progress:
            progress(len(local))
    if count == 0:
        raise PointCloudError(f"point cloud {path} holds no points.")
    if count != n_total:
        raise PointCloudError(
            f"point cloud {path}: header says {n_total} points but {count} were read (truncated?)."
        )
    area = max(float((hi[0] - lo[0]) * (hi[1] - lo[1])), 1e-6)
    names = {c.id: c.name for c in site.taxonomy.classes}
    return LasScan(
        path=str(path),
        source_crs=crs_text(src),
        transformed=tr is not None,
        point_count=count,
        bounds_min=lo.tolist(),
        bounds_max=hi.tolist(),
        class_histogram={names.get(i, str(i)): int(v) for i, v in enumerate(hist) if v},
        unknown_codes={i: int(v) for i, v in enumerate(unknown) if v},
        outside_fence=outside,
        colour=colour,
        density_pts_m2=count / area,
        version=version,
        point_format=pf,
        scale=scale,
        offset=offset,
        gps_time_range=[tmin, tmax] if np.isfinite(tmin) else None,
        z_unit=z_unit_of(src, z_unit).to_dict(),
        stable_sample=np.concatenate(samples) if samples else np.zeros((0, 3)),
    )
