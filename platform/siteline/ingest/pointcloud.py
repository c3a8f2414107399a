"""The one validating pass of ingest over a mission's LAS/LAZ (through :mod:`siteline.pointpass.partition`, in
parallel point ranges): statistics, unknown codes, and a sample of stable-class points for the
alignment check; the same pass cuts the points into tile runs that the tile stage takes over."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyproj

from siteline.errors import PointCloudError
from siteline.pointpass import (
    PARALLEL_MIN_POINTS,
    LasHeaderFacts,
    PassSource,
    SiteChunk,
    detect_eight_bit,
    header_facts,
    open_las,
    pass_file,
    source_crs,
    source_transformer,
    start_pool,
)
from siteline.progress import no_step
from siteline.records.scan import (
    COLOUR_NAMES,
    SAMPLE_STABLE,
    SAMPLE_STRUCTURE,
    STRETCH_PERCENTILES,
    ColourStats,
    LasScan,
    RgbContent,
)
from siteline.records.tiling import TileSpec
from siteline.site.crs import ZUnit, crs_text, z_unit_of
from siteline.site.fence import footprint
from siteline.site.spec import SiteSpec
from siteline.site.taxonomy import detect_scheme

# co-registration samples the stable surfaces (what point-to-plane ICP fixes first) and the structure
# of classes that do not come and go (what fixes the directions flat ground leaves free); construction
# classes (cranes, material, vehicles, workers, temporary works) change between epochs by design
STABLE_CLASSES = ("ground", "building")
STRUCTURE_CLASSES = ("vegetation", "unclassified")
# the most points of the all-class sample a scan keeps (every k-th point of the file)
SURVEY_SAMPLE_MAX = 50_000


def start_readers(mission_dir: Path, workers: int) -> None:
    """Start the ``workers`` processes that :func:`scan_las` reads a point cloud of the mission folder
    with (one of at least ``PARALLEL_MIN_POINTS`` points), so that they start up while the caller
    hashes the mission; an unreadable file is left to the scan to report."""
    if workers < 2:
        return
    for path in sorted(Path(mission_dir).rglob("*")):
        if path.suffix.lower() not in (".las", ".laz") or not path.is_file():
            continue
        try:
            with open_las(path) as reader:
                points = int(reader.header.point_count)
        except PointCloudError:
            continue
        if points >= PARALLEL_MIN_POINTS:
            start_pool(workers)
            return


# the stable-point sample a scan keeps (for co-registration): at most this many points, drawn with
# generators seeded by (SAMPLE_SEED, range), so a file's sample is the same on every ingest
SAMPLE_MAX = 200_000
SAMPLE_SEED = 0


def scan_las(
    path: Path,
    site: SiteSpec,
    crs_override: str | None = None,
    *,
    z_unit: ZUnit | None = None,
    progress: Callable[..., None] = no_step,
    workers: int = 1,
    runs_into: Path | None = None,
) -> LasScan:
    """Read ``path`` once, in parallel point ranges over ``workers`` processes: bring coordinates into
    the site CRS in float64, refuse non-finite or absurd ones, map classes through the site taxonomy,
    and gather statistics. z is converted to metres from ``z_unit`` (``--z-unit``) or the unit the
    file's CRS implies (recorded in the scan). ``runs_into``: an empty folder where the same pass
    cuts the points into tile runs on the site's default grid, for the tile stage
    (siteline.pointpass.partition; the caller keeps or removes it). ``progress(amount, total)`` receives the header's point count
    before reading and the points read as they go."""
    path = Path(path)
    with open_las(path) as reader:
        header = header_facts(reader.header)
        n_total = int(reader.header.point_count)
        src = source_crs(path, crs_override, reader)
        eight_bit = detect_eight_bit(reader, path) if n_total else None
    progress(0, n_total)
    tr = source_transformer(path, site, src, z_unit)
    source = PassSource(str(path), site, crs_text(src), z_unit_of(src, z_unit), eight_bit)
    names = {c.name for c in site.taxonomy.classes}
    kinds = np.zeros(256, np.uint8)
    kinds[[site.taxonomy.id_of(c) for c in STRUCTURE_CLASSES if c in names]] = SAMPLE_STRUCTURE
    kinds[[site.taxonomy.id_of(c) for c in STABLE_CLASSES]] = SAMPLE_STABLE
    keep_p = min(1.0, SAMPLE_MAX / max(n_total, 1))
    stride = max(1, -(-n_total // SURVEY_SAMPLE_MAX))
    spec = TileSpec.for_site(site)
    done = pass_file(
        source, n_total, workers, lambda k, start: (_Totals(kinds, keep_p, (SAMPLE_SEED, k), eight_bit, start, stride),),
        runs_into, spec, lambda _l, n, _t: progress(n),
    )  # fmt: skip
    t = _Totals(kinds, keep_p, (SAMPLE_SEED, 0), eight_bit, 0, stride)
    for (totals,) in done.visited:
        t.merge(totals)
    if t.count != n_total:
        raise PointCloudError(
            f"point cloud {path}: header says {n_total} points but {t.count} were read (truncated?)."
        )
    if done.partition is not None:
        done.partition.save(source.made_from(spec))
    if t.count == 0:
        raise PointCloudError(f"point cloud {path} holds no points.")
    return _scan(path, header, site, src, tr, z_unit, t)


class _Totals:
    """What the scan accumulates chunk by chunk."""

    def __init__(
        self,
        kinds: np.ndarray,
        keep_p: float,
        seed: tuple[int, int],
        eight_bit: bool | None,
        first: int,
        stride: int,
    ) -> None:
        self.kinds = kinds  # per class id: 0 not sampled, STABLE or STRUCTURE
        self.keep_p = keep_p
        self.rng = np.random.default_rng(list(seed))
        self.hist = np.zeros(256, np.int64)
        self.unknown = np.zeros(256, np.int64)
        self.codes = np.zeros(256, np.int64)
        self.lo, self.hi = np.full(3, np.inf), np.full(3, -np.inf)
        self.count = self.outside = 0
        self.tmin, self.tmax = np.inf, -np.inf
        self.samples: list[np.ndarray] = []
        self.colour = "none" if eight_bit is None else COLOUR_NAMES[eight_bit]
        # every stride-th point of the file (by its index: the same whatever the workers or origin),
        # all classes, with its intensity and site class: for planned cameras (the flight clears the
        # tallest structure), the footprint and colour statistics
        self.index, self.stride = first, stride
        self.survey: list[np.ndarray] = []
        self.rgb_lo, self.rgb_hi = np.full(3, 255), np.zeros(3, np.int64)

    def add(self, sc: SiteChunk) -> None:
        local, chunk, cls = sc.local, sc.chunk, sc.classes
        self.unknown += np.bincount(chunk.classification[~sc.known_code], minlength=256)
        self.codes += np.bincount(chunk.classification, minlength=256)
        self.outside += int(sc.outside.sum())
        self.hist += np.bincount(cls, minlength=256)
        self.lo = np.minimum(self.lo, sc.lo)
        self.hi = np.maximum(self.hi, sc.hi)
        self.count += len(local)
        if chunk.gps_time is not None and len(chunk.gps_time):
            # the range of finite times only: JSON has no Infinity (SQLite's JSON functions and
            # PostgreSQL refuse it) and NaN compares as nothing
            finite = chunk.gps_time[np.isfinite(chunk.gps_time)]
            if len(finite):
                self.tmin = min(self.tmin, float(finite.min()))
                self.tmax = max(self.tmax, float(finite.max()))
        kind = self.kinds[cls]
        sampled = np.flatnonzero(kind)
        sampled = sampled[self.rng.random(len(sampled)) < self.keep_p]
        self.samples.append(np.c_[local[sampled], kind[sampled]])
        take = np.arange(-self.index % self.stride, len(local), self.stride)
        self.survey.append(np.c_[local[take], chunk.intensity[take], cls[take]])
        self.index += len(local)
        if chunk.rgb is not None and len(local):
            self.rgb_lo = np.minimum(self.rgb_lo, chunk.rgb.min(axis=0))
            self.rgb_hi = np.maximum(self.rgb_hi, chunk.rgb.max(axis=0))

    def merge(self, other: _Totals) -> None:
        """Add the totals of another range."""
        self.unknown += other.unknown
        self.codes += other.codes
        self.outside += other.outside
        self.hist += other.hist
        self.lo, self.hi = np.minimum(self.lo, other.lo), np.maximum(self.hi, other.hi)
        self.count += other.count
        self.tmin, self.tmax = min(self.tmin, other.tmin), max(self.tmax, other.tmax)
        self.samples += other.samples
        self.survey += other.survey
        self.rgb_lo, self.rgb_hi = (
            np.minimum(self.rgb_lo, other.rgb_lo),
            np.maximum(self.rgb_hi, other.rgb_hi),
        )

    def colour_stats(self, survey: np.ndarray) -> ColourStats:
        """Whether the colour carries information, and the intensity and z stretches of the sample."""
        rgb: RgbContent = "absent" if self.colour == "none" else "constant"
        if rgb == "constant" and self.count and bool((self.rgb_hi > self.rgb_lo).any()):
            rgb = "varies"
        lo_i, hi_i = np.percentile(survey[:, 3], STRETCH_PERCENTILES) if len(survey) else (0.0, 0.0)
        lo_z, hi_z = np.percentile(survey[:, 2], STRETCH_PERCENTILES) if len(survey) else (0.0, 0.0)
        return ColourStats(
            rgb, (float(lo_i), float(hi_i)) if hi_i > lo_i else None, (float(lo_z), float(max(hi_z, lo_z)))
        )


def _scan(
    path: Path,
    header: LasHeaderFacts,
    site: SiteSpec,
    src: pyproj.CRS,
    tr: object,
    z_unit: ZUnit | None,
    t: _Totals,
) -> LasScan:
    area = max(float((t.hi[0] - t.lo[0]) * (t.hi[1] - t.lo[1])), 1e-6)
    survey = np.concatenate(t.survey) if t.survey else np.zeros((0, 5))
    outline = footprint(survey)
    names = {c.id: c.name for c in site.taxonomy.classes}
    codes = {i: int(v) for i, v in enumerate(t.codes) if v}
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
        code_histogram=codes,
        class_scheme=detect_scheme(codes, site.taxonomy),
        outside_fence=t.outside,
        colour=t.colour,
        density_pts_m2=t.count / area,
        version=header.version,
        point_format=header.point_format,
        scale=header.scales,
        offset=header.offsets,
        gps_time_range=[t.tmin, t.tmax] if np.isfinite(t.tmin) else None,
        z_unit=z_unit_of(src, z_unit),
        creation_date=day.isoformat() if day is not None else None,
        gps_time_standard=header.gps_time_standard,
        generating_software=header.software,
        colour_stats=t.colour_stats(survey),
        footprint=[list(v) for v in outline] if outline is not None else None,
        stable_sample=np.concatenate(t.samples) if t.samples else np.zeros((0, 4)),
        survey_sample=survey,
    )
