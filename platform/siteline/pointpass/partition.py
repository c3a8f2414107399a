"""One pass over a LAS/LAZ file in the site frame, in parallel point ranges, that cuts its points
into tile runs: records (siteline.pointpass.schema.RECORD) sorted by site-grid tile and block within each chunk, one
run file per range with a (tile and block, offset, count) row per chunk, tile and block. A block is
a column of a tile's level-0 cubes (:func:`block_edge`), so a tile's level of detail can be built a
few blocks at a time (siteline.tiles.batches). Ingest's scan rides the same pass (its
statistics are another visitor of each chunk), so a file is decoded once for ingest and tiling; the
tile writer gathers each tile's slices of the runs (siteline.tiles.writer).

A finished partition is kept under ``home/partitions/<key>``, the key a digest of everything that
decides its records (the file's content, the site frame, the source CRS and z unit, the colour
depth, the tile grid and quantum), until the tile stage claims it (an atomic rename) or it is swept.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple, Protocol

import numpy as np

from siteline.errors import StoreError, TileError
from siteline.pointpass.kernels import cut, radix, rows
from siteline.pointpass.schema import BLOCK_BITS, COUNT_LIMIT, COUNTS, RECORD, block_of, cell_ids, tile_of
from siteline.pointpass.sitestream import Correction, SiteChunk, SiteReading, site_chunks, source_transformer
from siteline.pointpass.workers import pool_map, process_pool
from siteline.progress import Progress, no_progress
from siteline.records.tiling import TileSpec
from siteline.schema import JSON, json_doc
from siteline.site.crs import ZUnit, parse_source_crs
from siteline.site.spec import SiteSpec
from siteline.stores.directio import append_blocks, finish_blocks
from siteline.stores.local import move
from siteline.stores.owners import owner_tag, sweep_stale

# below this many points one process does everything (a pool costs about half a second to start)
PARALLEL_MIN_POINTS = 2_000_000
# points per range: small enough to report progress and balance the workers
RANGE_POINTS = 4_000_000
# a kept partition nobody claimed within this many seconds is removed by the next pass
KEEP_S = 7 * 24 * 3600.0
_INDEX = "runs.npz"
_MADE_FROM = "made-from.json"


@dataclass(frozen=True)
class PassSource:
    """What a worker needs to read the file into the site frame (picklable): the file, the site, the
    source CRS text, the z unit (None: the unit the CRS implies), whether colour is 0-255 in 16-bit
    fields, and the co-registration applied to every point."""

    path: str
    site: SiteSpec
    crs: str
    z_unit: ZUnit | None
    eight_bit: bool | None
    correction: Correction | None = None

    def made_from(self, spec: TileSpec) -> dict[str, JSON]:
        """Everything but the file's content that decides the records of a partition of this source
        cut on ``spec``'s grid: the site frame, the source CRS and z unit, the colour depth, the tile
        grid and quantum, the record layout and the co-registration (when there is one)."""
        doc: dict[str, JSON] = {
            "site": json_doc(self.site.to_dict()), "crs": self.crs,
            "z_unit": self.z_unit.to_dict() if self.z_unit is not None else None,
            "eight_bit": bool(self.eight_bit), "tile_size_m": spec.tile_size_m, "quantum_m": spec.quantum_m,
            "block": block_edge(spec), "record": RECORD.descr, "format": 2,
        }  # fmt: skip
        if self.correction is not None:
            doc["correction"] = [list(row) for row in self.correction]
        return doc


def _key(made_from: dict[str, JSON], content_sha256: str) -> str:
    """The name of a partition: a digest of its file's content and of what else made its records."""
    doc = {**made_from, "sha256": content_sha256}
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()[:32]


class Slice(NamedTuple):
    """A tile's slice of one run of the partition: its block in the tile, the run file (a local path
    or, shared with a cluster, a URL), the first record and the number of records, and the lowest z count."""

    block: int
    path: str
    offset: int
    points: int
    zmin: int


class ChunkVisitor(Protocol):
    """What a pass hands every chunk of its range to (picklable: it travels to a worker and back)."""

    def add(self, sc: SiteChunk) -> None: ...


@dataclass(frozen=True)
class Run:
    """One range's run file (a name inside the partition folder): records sorted by tile and block
    within each chunk, and per (chunk, tile, block) a row of ``cell`` (:func:`cell_ids`), ``offset``
    (records), ``count`` and ``zmin`` (the lowest z count)."""

    name: str
    cell: np.ndarray
    offset: np.ndarray
    count: np.ndarray
    zmin: np.ndarray


def block_edge(spec: TileSpec) -> int:
    """The edge of a tile's blocks in quanta: a level-0 cube's (the tile when a level-0 cube is
    larger, or when a tile would need more than 256 blocks a side)."""
    tile_q = spec.tile_quanta
    edge = max(int(round(spec.level0_spacing_m / spec.quantum_m)), 1)
    return tile_q if edge >= tile_q or -(-tile_q // edge) > 1 << (BLOCK_BITS // 2) else edge


def blocks_per_side(spec: TileSpec) -> int:
    tile_q = spec.tile_quanta
    return -(-tile_q // block_edge(spec))


def chunk_records(sc: SiteChunk, spec: TileSpec) -> tuple[np.ndarray, np.ndarray]:
    """A chunk's records sorted by tile and block (a stable radix sort of their codes) and a row per
    cell (:func:`cell_ids`) it touches: (cell, first record, records, lowest z count). A block is row-major
    ``by * blocks_per_side + bx`` of the tile's counts floored by :func:`block_edge` (a point rounded
    onto the tile's far edge stays in the last block)."""
    n = len(sc.local)
    side = blocks_per_side(spec)
    counts = np.empty((n, 3), np.int32)
    code = np.empty(n, np.int64)
    local = np.ascontiguousarray(sc.local, dtype=np.float64)
    lo_i, lo_j, span_j, far = cut.tile_codes(
        local, spec.tile_size_m, spec.quantum_m, block_edge(spec), side, counts, code
    )
    if far >= COUNT_LIMIT:
        raise TileError(
            f"a point lies {far * spec.quantum_m:,.0f} m from its tile's origin (z from the site origin): "
            f"more than int32 counts of the {spec.quantum_m} m quantum reach; is the quantum right?"
        )
    order = radix.radix_order(code)
    code = code[order]
    ch = sc.chunk
    rec = np.empty(n, RECORD)
    rows.scatter_records(
        radix.inverse(order), counts, ch.rgb if ch.rgb is not None else np.zeros((n, 3), np.uint8),
        ch.intensity, sc.classes, ch.gps_time if ch.gps_time is not None else np.zeros(n),
        ch.return_number, rec,
    )  # fmt: skip
    first = radix.run_starts(code)
    zmin = np.minimum.reduceat(rec[COUNTS][:, 2], first) if n else np.zeros(0, np.int32)
    tile, block = code[first] // (side * side), code[first] % (side * side)
    tij = np.c_[tile // span_j + lo_i, tile % span_j + lo_j]
    return rec, np.c_[cell_ids(tij, block), first, np.diff(np.r_[first, n]), zmin.astype(np.int64)]


@dataclass
class RunWriter:
    """A visitor that appends each chunk's records, sorted by tile and block, to the run file
    ``folder/name``, around the page cache (siteline.stores.directio): whole blocks as it goes, the last
    bytes (``tail``, under a block) when :meth:`run` closes it."""

    folder: str
    name: str
    spec: TileSpec
    rows: list[np.ndarray] = field(default_factory=list)
    written: int = 0
    tail: bytes = b""

    def add(self, sc: SiteChunk) -> None:
        rec, rows = chunk_records(sc, self.spec)
        at = self.written * RECORD.itemsize - len(self.tail)
        self.tail = append_blocks(self._path, at, self.tail, rec.view(np.uint8).data)
        rows[:, 1] += self.written
        self.rows.append(rows)
        self.written += len(rec)

    @property
    def _path(self) -> str:
        return os.path.join(self.folder, self.name)

    def run(self) -> Run:
        """The run, its file complete."""
        if self.tail:
            finish_blocks(self._path, self.written * RECORD.itemsize - len(self.tail), self.tail)
            self.tail = b""
        table = np.concatenate(self.rows) if self.rows else np.zeros((0, 4), np.int64)
        return Run(self.name, *table.T)


def read_range(source: PassSource, start: int, stop: int, visitors: tuple[Any, ...]) -> tuple[Any, ...]:
    """Hand every chunk of points [start, stop) of the file, in the site frame, to each visitor (runs
    in a worker process); return the visitors."""
    path = Path(source.path)
    tr = source_transformer(path, source.site, parse_source_crs(source.crs), source.z_unit)
    how = SiteReading(start, stop, eight_bit=source.eight_bit, correction=source.correction)
    chunks = site_chunks(path, source.site, tr, how)
    for sc in chunks:
        for v in visitors:
            try:
                v.add(sc)
            except TileError as e:
                raise TileError(f"point cloud {path}: {e}") from e
    return visitors


def point_ranges(total: int, workers: int) -> list[tuple[int, int]]:
    """Point ranges of a file: about ``RANGE_POINTS`` each, at least one per worker when it is big
    enough for a pool, cut at whole LAZ chunks (laszip's default 50,000 points)."""
    if total <= 0:
        return [(0, 0)]
    pieces = max(workers if total >= PARALLEL_MIN_POINTS else 1, -(-total // RANGE_POINTS), 1)
    size = -(-total // pieces)
    size = -(-size // 50_000) * 50_000
    return [(a, min(a + size, total)) for a in range(0, total, size)]


def read_file(
    source: PassSource,
    total: int,
    visitors: Sequence[tuple[Any, ...]],
    workers: int,
    progress: Progress = no_progress,
    label: str = "reading points",
) -> Iterator[tuple[Any, ...]]:
    """One pass over the file's ``point_ranges(total, workers)``: range k's chunks go to
    ``visitors[k]``; yields each range's visitors in order (from worker processes when the file is
    big enough and ``workers`` > 1)."""
    ranges = point_ranges(total, workers)
    if len(visitors) != len(ranges):
        raise ValueError(f"{len(ranges)} ranges but {len(visitors)} visitor sets")
    pool = process_pool(workers) if workers > 1 and total >= PARALLEL_MIN_POINTS else None
    starts, stops = (list(v) for v in zip(*ranges, strict=True))
    for (a, b), done in zip(
        ranges, pool_map(pool, read_range, [source] * len(ranges), starts, stops, visitors), strict=True
    ):
        progress(label, b - a, total)
        yield done


@dataclass(frozen=True)
class PassResult:
    """What one pass over a file gave: each point range's own visitors, in range order, and the
    partition of its points into tile runs (None when none was asked for)."""

    visited: list[tuple[Any, ...]]
    partition: Partition | None


def pass_file(
    source: PassSource,
    total: int,
    workers: int,
    visitors: Callable[[int, int], tuple[Any, ...]] = lambda k, start: (),
    runs_into: Path | None = None,
    spec: TileSpec | None = None,
    progress: Progress = no_progress,
    label: str = "reading points",
) -> PassResult:
    """The engine's entry: one pass over the ``total`` points of ``source`` in parallel point ranges
    over ``workers`` processes. ``visitors(k, start)`` makes range k's own chunk visitors (its first
    point is ``start``); ``runs_into``: an empty local folder where the same pass cuts the points into
    tile runs on ``spec``'s grid (None: the site's default)."""
    ranges = point_ranges(total, workers)
    spec = spec or TileSpec.for_site(source.site)
    sets = [
        visitors(k, start) + ((RunWriter(str(runs_into), f"run-{k:05d}.bin", spec),) if runs_into else ())
        for k, (start, _) in enumerate(ranges)
    ]
    own = len(sets[0]) - (runs_into is not None) if sets else 0
    visited, runs = [], []
    for done in read_file(source, total, sets, workers, progress, label):
        visited.append(done[:own])
        runs += [v.run() for v in done[own:]]
    return PassResult(visited, Partition(runs_into, tuple(runs)) if runs_into is not None else None)


@dataclass(frozen=True)
class Partition:
    """A file's runs in ``folder`` (a local path)."""

    folder: Path
    runs: tuple[Run, ...]

    def parts_by_tile(self) -> dict[tuple[int, int], list[Slice]]:
        """Per tile (i, j), its slices (block, run file path, offset, count, lowest z count) by
        block, then in run order."""
        runs = self.runs
        cols = [np.concatenate([getattr(r, c) for r in runs]) for c in ("cell", "offset", "count", "zmin")]
        which = np.concatenate([np.full(len(r.cell), k) for k, r in enumerate(runs)])
        order = np.argsort(cols[0], kind="stable")
        out: dict[tuple[int, int], list[Slice]] = {}
        rows = zip(*(c[order].tolist() for c in (cols[0], which, *cols[1:])), strict=True)
        for cell, k, off, c, z in rows:
            out.setdefault(tile_of(cell), []).append(
                Slice(block_of(cell), str(self.folder / runs[k].name), off, c, z)
            )
        return out

    def save(self, made_from: dict[str, JSON] | None = None) -> None:
        """Write the index of the runs beside them, and what made them (:meth:`PassSource.made_from`:
        how a :class:`PartitionCache` names the partition it keeps)."""
        if made_from is not None:
            (self.folder / _MADE_FROM).write_text(json.dumps(made_from, sort_keys=True, default=str))
        np.savez(
            self.folder / _INDEX,
            names=np.array([r.name for r in self.runs]),
            lengths=np.array([len(r.cell) for r in self.runs], np.int64),
            table=np.concatenate(
                [np.c_[r.cell, r.offset, r.count, r.zmin] for r in self.runs] or [np.zeros((0, 4), np.int64)]
            ),
        )

    @classmethod
    def load(cls, folder: Path) -> Partition:
        with np.load(folder / _INDEX) as doc:
            names, lengths, table = doc["names"].tolist(), doc["lengths"], doc["table"]
        at = np.r_[0, np.cumsum(lengths)]
        runs = tuple(Run(name, *table[a:b].T) for name, a, b in zip(names, at[:-1], at[1:], strict=True))
        return cls(folder, runs)


@dataclass(frozen=True)
class PartitionCache:
    """The partitions ingest keeps for the tile stage, in ``folder`` (``SITELINE_HOME/partitions``),
    each named by a digest of its file's content and of what else made its records (the one place
    the name is made): ingest cuts a file into a :meth:`new_folder` as it scans it and :meth:`keep`
    s it; the tile stage :meth:`claim` s the one that matches what it would cut, or cuts anew."""

    folder: Path

    def sweep_unfinished(self) -> None:
        """Remove partitions a killed ingest was writing (their owner is provably gone)."""
        if self.folder.is_dir():
            sweep_stale(self.folder, ".new-*")

    def new_folder(self) -> Path:
        """A fresh folder for a partition being written (owner-tagged; provably stale ones are swept,
        and kept ones older than ``KEEP_S``)."""
        self.folder.mkdir(parents=True, exist_ok=True)
        self.sweep_unfinished()
        now = time.time()
        for kept in self.folder.iterdir():
            if not kept.name.startswith(".") and now - kept.stat().st_mtime > KEEP_S:
                shutil.rmtree(kept, ignore_errors=True)
        folder = self.folder / f".new-{owner_tag()}"
        folder.mkdir()
        return folder

    def keep(self, runs: Path, content_sha256: str) -> bool:
        """Keep the saved partition ``runs`` (a :meth:`new_folder`) of a file with content
        ``content_sha256`` for the tile stage, replacing one of the same name; False (nothing kept)
        when it does not record what made it."""
        try:
            made_from = json.loads((runs / _MADE_FROM).read_text())
        except (OSError, ValueError):
            return False
        move(runs, self.folder / _key(made_from, content_sha256), replace=True)
        return True

    def claim(self, source: PassSource, content_sha256: str, spec: TileSpec, into: Path) -> Partition | None:
        """Take the kept partition of ``source`` (content ``content_sha256``) cut on ``spec``'s grid,
        moved to ``into`` so no other caller gets it; None when there is none or it cannot be read."""
        try:
            move(self.folder / _key(source.made_from(spec), content_sha256), into)
        except (OSError, StoreError):
            return None
        try:
            return Partition.load(into)
        except (OSError, ValueError, KeyError, IndexError, TypeError):
            shutil.rmtree(into, ignore_errors=True)
            return None
