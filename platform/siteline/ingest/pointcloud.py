"""The one validating pass of ingest over a mission's LAS/LAZ (through :mod:`siteline.sitestream`):
statistics, unknown codes, and a sample of stable-class points for the alignment check."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import laspy
import numpy as np

from siteline.crs import ZUnit, crs_text, z_unit_of
from siteline.errors import PointCloudError
from siteline.lasio import DEFAULT_CHUNK_POINTS, open_las
from siteline.site import SiteSpec
from siteline.sitestream import site_chunks, source_crs, source_transformer

STABLE_CLASSES = ("ground", "building")


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
    creation_date: str | None
    stable_sample: np.ndarray = field(repr=False)

    def to_dict(self) -> dict:
        d = {k: v for k, v in self.__dict__.items() if k != "stable_sample"}
        d["unknown_codes"] = {str(k): v for k, v in self.unknown_codes.items()}
        return d


def scan_las(
    path: Path,
    site: SiteSpec,
    crs_override: str | None = None,
    *,
    z_unit: ZUnit | None = None,
    sample_max: int = 200_000,
    chunk_points: int = DEFAULT_CHUNK_POINTS,
    progress: Callable[[int], None] | None = None,
    total: Callable[[int], None] | None = None,
    seed: int = 0,
) -> LasScan:
    """Read ``path`` once in chunks (one open of the file): bring coordinates into the site CRS in
    float64, refuse non-finite or absurd ones, map classes through the site taxonomy, and gather
    statistics. z is converted to metres from ``z_unit`` (``--z-unit``) or the unit the file's CRS
    implies (recorded in the scan). ``total`` receives the header's point count before reading,
    ``progress`` the points read as they go."""
    path = Path(path)
    with open_las(path) as reader:
        return _scan(
            reader, path, site, crs_override, z_unit, sample_max, chunk_points, progress, total, seed
        )


def _scan(
    reader: laspy.LasReader,
    path: Path,
    site: SiteSpec,
    crs_override: str | None,
    z_unit: ZUnit | None,
    sample_max: int,
    chunk_points: int,
    progress: Callable[[int], None] | None,
    total: Callable[[int], None] | None,
    seed: int,
) -> LasScan:
    header = reader.header
    n_total = int(header.point_count)
    version = f"{header.version.major}.{header.version.minor}"
    pf = int(header.point_format.id)
    scale = [float(v) for v in header.scales]
    offset = [float(v) for v in header.offsets]
    day = header.creation_date
    if total:
        total(n_total)
    if not (np.isfinite(scale).all() and np.isfinite(offset).all()) or min(abs(s) for s in scale) == 0:
        raise PointCloudError(
            f"point cloud {path}: header scale {scale} / offset {offset} is not finite and non-zero."
        )
    src = source_crs(path, crs_override, reader)
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
    for sc in site_chunks(path, site, tr, chunk_points, reader=reader):
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
        creation_date=day.isoformat() if day is not None else None,
        stable_sample=np.concatenate(samples) if samples else np.zeros((0, 3)),
    )
