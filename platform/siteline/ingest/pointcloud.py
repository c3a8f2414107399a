"""The one validating pass of ingest over a mission's LAS/LAZ (through :mod:`siteline.sitestream`):
statistics, unknown codes, and a sample of stable-class points for the alignment check."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import laspy
import numpy as np

from siteline.crs import ZUnit, crs_text, z_unit_of
from siteline.errors import PointCloudError
from siteline.lasio import DEFAULT_CHUNK_POINTS, open_las
from siteline.progress import no_step
from siteline.records.scan import LasScan
from siteline.site import SiteSpec
from siteline.sitestream import SiteChunk, site_chunks, source_crs, source_transformer

STABLE_CLASSES = ("ground", "building")


def scan_las(
    path: Path,
    site: SiteSpec,
    crs_override: str | None = None,
    *,
    z_unit: ZUnit | None = None,
    sample_max: int = 200_000,
    chunk_points: int = DEFAULT_CHUNK_POINTS,
    progress: Callable[..., None] = no_step,
    seed: int = 0,
) -> LasScan:
    """Read ``path`` once in chunks (one open of the file): bring coordinates into the site CRS in
    float64, refuse non-finite or absurd ones, map classes through the site taxonomy, and gather
    statistics. z is converted to metres from ``z_unit`` (``--z-unit``) or the unit the file's CRS
    implies (recorded in the scan). ``progress(amount, total)`` receives the header's point count
    before reading and the points read as they go."""
    path = Path(path)
    with open_las(path) as reader:
        return _scan(reader, path, site, crs_override, z_unit, sample_max, chunk_points, progress, seed)


class _Totals:
    """What the scan accumulates chunk by chunk."""

    def __init__(self, stable_ids: np.ndarray, keep_p: float, seed: int) -> None:
        self.stable_ids, self.keep_p = stable_ids, keep_p
        self.rng = np.random.default_rng(seed)
        self.hist = np.zeros(256, np.int64)
        self.unknown = np.zeros(256, np.int64)
        self.lo, self.hi = np.full(3, np.inf), np.full(3, -np.inf)
        self.count = self.outside = 0
        self.tmin, self.tmax = np.inf, -np.inf
        self.samples: list[np.ndarray] = []
        self.colour = "none"

    def add(self, sc: SiteChunk) -> None:
        local, chunk, cls = sc.local, sc.chunk, sc.classes
        self.unknown += np.bincount(chunk.classification[~sc.known_code], minlength=256)
        self.outside += int(sc.outside.sum())
        self.hist += np.bincount(cls, minlength=256)
        self.lo = np.minimum(self.lo, local.min(axis=0))
        self.hi = np.maximum(self.hi, local.max(axis=0))
        self.count += len(local)
        if chunk.gps_time is not None and len(chunk.gps_time):
            self.tmin = min(self.tmin, float(chunk.gps_time.min()))
            self.tmax = max(self.tmax, float(chunk.gps_time.max()))
        if chunk.rgb is not None:
            self.colour = "rgb 8-bit stored in 16-bit fields" if chunk.colour_8bit else "rgb 16-bit"
        stable = np.isin(cls, self.stable_ids) & (self.rng.random(len(cls)) < self.keep_p)
        self.samples.append(local[stable])


def _scan(
    reader: laspy.LasReader,
    path: Path,
    site: SiteSpec,
    crs_override: str | None,
    z_unit: ZUnit | None,
    sample_max: int,
    chunk_points: int,
    progress: Callable[..., None],
    seed: int,
) -> LasScan:
    header = reader.header
    n_total = int(header.point_count)
    progress(0, n_total)
    src = source_crs(path, crs_override, reader)
    tr = source_transformer(path, site, src, z_unit)
    stable_ids = np.array([site.taxonomy.id_of(c) for c in STABLE_CLASSES], dtype=np.uint8)
    t = _Totals(stable_ids, min(1.0, sample_max / max(n_total, 1)), seed)
    for sc in site_chunks(path, site, tr, chunk_points, reader=reader):
        t.add(sc)
        progress(len(sc.local))
    if t.count == 0:
        raise PointCloudError(f"point cloud {path} holds no points.")
    if t.count != n_total:
        raise PointCloudError(
            f"point cloud {path}: header says {n_total} points but {t.count} were read (truncated?)."
        )
    area = max(float((t.hi[0] - t.lo[0]) * (t.hi[1] - t.lo[1])), 1e-6)
    names = {c.id: c.name for c in site.taxonomy.classes}
    day = header.creation_date
    return LasScan(
        path=str(path),
        source_crs=crs_text(src),
        transformed=tr is not None,
        point_count=t.count,
        bounds_min=t.lo.tolist(),
        bounds_max=t.hi.tolist(),
        class_histogram={names.get(i, str(i)): int(v) for i, v in enumerate(t.hist) if v},
        unknown_codes={i: int(v) for i, v in enumerate(t.unknown) if v},
        outside_fence=t.outside,
        colour=t.colour,
        density_pts_m2=t.count / area,
        version=f"{header.version.major}.{header.version.minor}",
        point_format=int(header.point_format.id),
        scale=[float(v) for v in header.scales],
        offset=[float(v) for v in header.offsets],
        gps_time_range=[t.tmin, t.tmax] if np.isfinite(t.tmin) else None,
        z_unit=z_unit_of(src, z_unit).to_dict(),
        creation_date=day.isoformat() if day is not None else None,
        stable_sample=np.concatenate(t.samples) if t.samples else np.zeros((0, 3)),
    )
