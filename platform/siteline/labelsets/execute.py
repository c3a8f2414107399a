"""Importing corrected semantic labels into a label-set store (the execute part of the import; never
touches the catalog).

The file (LAS/LAZ, typically a ``siteline scene export`` corrected in CloudCompare, DJI Modify or any
LAS editor) is streamed once into per-tile spill files, then each tile's stored points are matched to
the file's points (siteline.labelsets.match) and the tile's classes are written: the file's class
where a point matched, the previous version's elsewhere (so a region export is corrected alone). The
store is published whole; on any refusal nothing is left.
"""

from __future__ import annotations

import contextlib
import logging
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import zarr

from siteline.errors import LabelSetError, SchemaError
from siteline.hashing import sha256_file
from siteline.labelsets.compare import changes_by_class, histogram, pair_counts
from siteline.labelsets.mapping import TaxonomyMap, coding_lut
from siteline.labelsets.match import match_points, point_keys
from siteline.labelsets.plan import ImportPlan
from siteline.labelsets.store import open_labelled, write_tile_classes
from siteline.pointpass import (
    SiteReading,
    file_crs,
    open_las,
    quantise,
    read_labels_vlr,
    site_chunks,
    source_transformer,
)
from siteline.progress import Progress, no_progress
from siteline.records.labelsets import ExportedLabels, LabelSetImport
from siteline.site.spec import SiteSpec
from siteline.site.taxonomy import Taxonomy
from siteline.stores import Store, layout
from siteline.stores.owners import owner_tag, sweep_stale
from siteline.tiles.layout import parse_tile_key, tile_index, tile_key, tile_origin_local
from siteline.tiles.reader import SceneTiles

log = logging.getLogger(__name__)

# Refuse a file when more than this fraction of its points match no stored point or match one
# already taken: an editor that keeps points never creates either, so anything above rounding
# noise means another scene, a merged or re-sampled file, or moved points.
DEFAULT_MAX_UNMATCHED = 0.001
SPILL_PREFIX = "labels-scene-"

SPILL_DTYPE = np.dtype(
    [
        ("idx", "<i8"),
        ("local", "<f8", (3,)),
        ("gps_time", "<f8"),
        ("return_number", "u1"),
        ("class", "u1"),
        ("edge", "?"),
    ]
)


class _Unchanged(Exception):
    """No point changed class: the store under construction is dropped."""


@dataclass
class MatchCounts:
    """How a file's points matched a scene's, over every tile (see :func:`_match_tiles`)."""

    matched: int = 0
    unmatched: int = 0
    duplicated: int = 0
    untouched: int = 0
    changed: int = 0
    changes: dict[str, int] = field(default_factory=dict)
    histogram: dict[str, int] = field(default_factory=dict)
    conflicts: int = 0


def _check_origin(
    about: ExportedLabels | None, scene_id: int, site: SiteSpec, path: Path, taxonomy_map: TaxonomyMap
) -> None:
    """Refuse a file whose siteline record says it was exported from another scene or site, and,
    without ``taxonomy_map``, one whose codes cannot be known to be the site's class ids: no siteline
    record (ASPRS codes 2 and 5 would read as the site's classes 2 and 5), or a record of another
    taxonomy (the site's was updated since the export)."""
    if about is not None and (about.site != site.name or about.scene != scene_id):
        raise LabelSetError(
            f"labels file {path} was exported from scene {about.scene} of site {about.site}, "
            f"not scene {scene_id} of site {site.name}: import it into that scene. Nothing was written."
        )
    if taxonomy_map is not None:
        return
    how = (
        "Give --taxonomy-map FILE (a JSON map of code -> class), --taxonomy-map las (the site taxonomy's LAS "
        "codes, e.g. ASPRS) or --taxonomy-map site (they are this site's class ids). Nothing was written."
    )
    if about is None:
        names = {c.id: c.name for c in site.taxonomy.classes}
        raise LabelSetError(
            f"labels file {path} carries no siteline label-set record (`siteline scene export` writes one; an "
            f"editor may drop it), so its class codes cannot be taken as site {site.name}'s class ids (ASPRS 2 "
            f"and 5 would read as {names.get(2, 'nothing')} and {names.get(5, 'nothing')}). {how}"
        )
    try:
        recorded = Taxonomy.from_dict(about.taxonomy, f"labels file {path}'s label-set record: its taxonomy")
        ids = {c.id: c.name for c in recorded.classes}
    except SchemaError:  # a taxonomy an editor mangled (or dropped) is not the site's: refused below
        ids = {}
    if ids != {c.id: c.name for c in site.taxonomy.classes}:
        raise LabelSetError(
            f"labels file {path} was exported under taxonomy {about.taxonomy.get('name')!r}, whose "
            f"class ids differ from site {site.name}'s taxonomy {site.taxonomy.name!r} now. {how}"
        )


def _spill_chunk(rec: np.ndarray, local: np.ndarray, tiles: SceneTiles, spill_dir: Path) -> None:
    """Append the points ``rec`` (site-local ``local``) to their tiles' spill files; a point within
    one quantum of a tile edge goes to the neighbouring tile(s) too (and is marked ``edge``)."""
    size, q = tiles.spec.tile_size_m, tiles.spec.quantum_m
    ij = tile_index(local, size)
    frac = local[:, :2] / size - ij
    step = np.where(frac * size < q, -1, np.where((1 - frac) * size < q, 1, 0))
    rec["edge"] = step.any(axis=1)
    for dx, dy in ((0, 0), (1, 0), (0, 1), (1, 1)):
        sel = np.ones(len(rec), dtype=bool)
        if dx:
            sel &= step[:, 0] != 0
        if dy:
            sel &= step[:, 1] != 0
        if not sel.any():
            continue
        cand = ij[sel] + step[sel] * np.array([dx, dy])
        order = np.lexsort((cand[:, 1], cand[:, 0]))
        cand_sorted = cand[order]
        cuts = np.flatnonzero(np.any(np.diff(cand_sorted, axis=0) != 0, axis=1)) + 1
        part_rec = rec[sel][order]
        for lo, hi in zip(np.r_[0, cuts], np.r_[cuts, len(order)], strict=True):
            key = tile_key(int(cand_sorted[lo, 0]), int(cand_sorted[lo, 1]))
            if key in tiles.by_tile:
                with open(spill_dir / f"{key}.bin", "ab") as fh:
                    part_rec[lo:hi].tofile(fh)


def _spill(
    path: Path, plan: ImportPlan, tiles: SceneTiles, lut: tuple[np.ndarray, np.ndarray], spill_dir: Path,
    progress: Progress, taxonomy_map: TaxonomyMap = "site",
) -> tuple[int, bool, np.ndarray]:  # fmt: skip
    """Stream the file into per-tile spill files; return its point count, whether it has GPS times,
    and the count per unknown code."""
    site = plan.site
    unknown = np.zeros(256, dtype=np.int64)
    n = 0
    with open_las(path) as reader:
        doc = read_labels_vlr(reader.header, path)
        _check_origin(
            ExportedLabels.from_dict(doc) if doc is not None else None,
            plan.scene_id,
            site,
            path,
            taxonomy_map,
        )
        has_time = "gps_time" in reader.header.point_format.dimension_names
        crs = file_crs(reader, path) or site.pyproj_crs  # an editor may drop the CRS: it is the export's
        tr = source_transformer(path, site, crs)
        # the file's coordinates are the tiles' (rounded to the quantum): ingest's inside stays inside
        how = SiteReading(class_lut=lut, fence_tol_m=tiles.spec.quantum_m)
        for sc in site_chunks(path, site, tr, how, reader=reader):
            unknown += np.bincount(sc.chunk.classification[~sc.known_code], minlength=256)
            rec = np.empty(len(sc.local), SPILL_DTYPE)
            rec["idx"] = np.arange(n, n + len(rec))
            rec["local"] = sc.local
            rec["gps_time"] = sc.chunk.gps_time if has_time and sc.chunk.gps_time is not None else 0.0
            rec["return_number"] = sc.chunk.return_number
            rec["class"] = sc.classes
            _spill_chunk(rec, sc.local, tiles, spill_dir)
            n += len(rec)
            progress("reading labels", len(rec), None)
    return n, has_time, unknown


def _match_tile(
    tiles: SceneTiles, tile: str, inc: np.ndarray, has_time: bool, base: SceneTiles | None = None
) -> tuple[np.ndarray, np.ndarray, Any, int]:
    """The stored classes of ``tile``, its new classes with the spilled file points ``inc`` matched
    in, the match (siteline.labelsets.match) and the conflicts. With ``base`` (the label set the file
    was exported from, older than the stored one), only the file's changes from the base are
    written over the stored classes, and a point both changed (to different classes) is a conflict."""
    spec = tiles.spec
    origin = tile_origin_local(*parse_tile_key(tile), spec.tile_size_m)
    data = tiles.read_tile(tile, ("gps_time", "return_number", "class"))
    attrs = data.attributes
    stored = point_keys(
        quantise(data.xyz_m, origin, spec.quantum_m),
        attrs["gps_time"] if has_time else None,
        attrs["return_number"],
    )
    incoming = point_keys(
        quantise(inc["local"], origin, spec.quantum_m),
        inc["gps_time"] if has_time else None,
        inc["return_number"],
    )
    m = match_points(stored, incoming)
    new = attrs["class"].copy()
    theirs = inc["class"][m.incoming]
    if base is None:
        new[m.stored] = theirs
        return attrs["class"], new, m, 0
    was = base.read_tile(tile, ("class",)).attributes["class"][m.stored]
    mine = attrs["class"][m.stored]
    edited = theirs != was
    conflicts = int((edited & (mine != was) & (theirs != mine)).sum())
    new[m.stored[edited]] = theirs[edited]
    return attrs["class"], new, m, conflicts


def _match_tiles(
    tiles: SceneTiles, spill_dir: Path, has_time: bool, work: Path, site: SiteSpec, n_file: int,
    progress: Progress, base: SceneTiles | None = None,
) -> MatchCounts:  # fmt: skip
    """Match every tile's stored points to its spilled file points and write the tile's classes. A
    file point near a tile edge was spilled to both tiles: once matched it is skipped in the next;
    it is a duplicate only if no tile matched it; a point spilled nowhere (no such tile) or matched
    by no tile's key is unmatched."""
    group = zarr.open_group(str(work), mode="w")
    taken_edge: list[np.ndarray] = []
    dup_edge: list[np.ndarray] = []
    out = MatchCounts()
    dup_inner = 0
    counts = np.zeros((256, 256), dtype=np.int64)
    keys = sorted(tiles.by_tile)
    for tile in keys:
        spill = spill_dir / f"{tile}.bin"
        inc = np.fromfile(spill, dtype=SPILL_DTYPE) if spill.exists() else np.zeros(0, SPILL_DTYPE)
        if taken_edge and inc["edge"].any():
            inc = inc[~(inc["edge"] & np.isin(inc["idx"], np.concatenate(taken_edge)))]
        old, new, m, conflicts = _match_tile(tiles, tile, inc, has_time, base)
        out.conflicts += conflicts
        counts += pair_counts(old, new)
        write_tile_classes(group, tile, new, tiles.spec)
        hit, dup = inc[m.incoming], inc[m.duplicated]
        taken_edge.append(hit["idx"][hit["edge"]])
        dup_edge.append(dup["idx"][dup["edge"]])
        dup_inner += int((~dup["edge"]).sum())
        out.matched += len(m.stored)
        out.untouched += len(old) - len(m.stored)
        progress("matching tiles", 1, len(keys))
    taken = np.concatenate(taken_edge) if taken_edge else np.zeros(0, np.int64)
    dup_edge_idx = np.concatenate(dup_edge) if dup_edge else np.zeros(0, np.int64)
    out.duplicated = dup_inner + len(np.setdiff1d(dup_edge_idx, taken))
    out.unmatched = n_file - out.matched - out.duplicated
    out.changed = int(counts.sum() - np.trace(counts))
    out.changes = changes_by_class(counts, site.taxonomy)
    out.histogram = histogram(counts, site.taxonomy)
    return out


def _refuse_unknown(path: Path, plan: ImportPlan, unknown: np.ndarray, mapped: bool) -> None:
    if not unknown.any():
        return
    codes = {int(c): int(unknown[c]) for c in np.nonzero(unknown)[0]}
    hint = "add them to the taxonomy map" if mapped else "map them with --taxonomy-map"
    raise LabelSetError(
        f"labels file {path}: class codes {sorted(codes)} ({sum(codes.values()):,} points) are not classes "
        f"of site {plan.site.name}'s taxonomy (ids {sorted(c.id for c in plan.site.taxonomy.classes)}): "
        f"{hint}. Nothing was written."
    )


def _refuse_conflicts(path: Path, plan: ImportPlan, m: MatchCounts) -> None:
    """Refuse a merge in which both the file and the label sets imported since its export changed
    the same points to different classes."""
    if m.conflicts and plan.base is not None:
        raise LabelSetError(
            f"labels file {path} was exported from label set {plan.base.version} of scene {plan.scene_id}; "
            f"since then label set {plan.parent.version} changed {m.conflicts:,} of the points it changes, to "
            f"other classes. Export label set {plan.parent.version}, redo those corrections on it and import "
            "that. Nothing was written."
        )


def _refuse_poor_match(
    path: Path, plan: ImportPlan, m: MatchCounts, n_file: int, max_unmatched: float
) -> None:
    bad = m.unmatched + m.duplicated
    if m.matched == 0 or bad > max_unmatched * n_file:
        raise LabelSetError(
            f"labels file {path}: {m.unmatched:,} of its {n_file:,} points match no point of scene "
            f"{plan.scene_id} and {m.duplicated:,} repeat a point already matched ({bad / n_file:.2%}, limit "
            f"{max_unmatched:.2%}): is it an export of scene {plan.scene_id}, unmoved and not merged or "
            "resampled? Nothing was written."
        )


def execute_label_import(
    plan: ImportPlan, path: Path, store: Store, scratch: Path,
    taxonomy_map: TaxonomyMap = None, note: str | None = None,
    max_unmatched: float = DEFAULT_MAX_UNMATCHED, progress: Progress = no_progress,
) -> LabelSetImport:  # fmt: skip
    """Match the classes of ``path`` to the scene of ``plan`` and publish them as the store of
    ``plan.version`` (``created`` False, and nothing stored, when no point changes class). Spill
    files go to a folder of ``scratch`` that is removed at the end."""
    t0 = time.perf_counter()
    try:
        lut = coding_lut(plan.site.taxonomy, taxonomy_map)
    except LabelSetError as exc:
        raise LabelSetError(f"labels file {path}: {exc}") from exc
    sha = sha256_file(path)
    uri = layout.label_set(store, plan.scene_id, plan.version)
    store.remove(uri)  # a store a crashed import published without its row
    tiles = open_labelled(plan.tiles, plan.parent)
    scratch.mkdir(parents=True, exist_ok=True)
    sweep_stale(scratch, f"{SPILL_PREFIX}*")
    spill_dir = Path(tempfile.mkdtemp(prefix=f"{SPILL_PREFIX}{plan.scene_id}-{owner_tag()}-", dir=scratch))
    m = MatchCounts()
    try:
        n_file, has_time, unknown = _spill(path, plan, tiles, lut, spill_dir, progress, taxonomy_map)
        _refuse_unknown(path, plan, unknown, taxonomy_map is not None)
        if n_file == 0:
            raise LabelSetError(f"labels file {path} holds no points. Nothing was written.")
        with contextlib.suppress(_Unchanged), store.publish(uri) as work:
            base = open_labelled(plan.tiles, plan.base) if plan.merging and plan.base is not None else None
            m = _match_tiles(tiles, spill_dir, has_time, work, plan.site, n_file, progress, base)
            _refuse_poor_match(path, plan, m, n_file, max_unmatched)
            _refuse_conflicts(path, plan, m)
            if m.changed == 0:
                raise _Unchanged
            zarr.open_group(str(work), mode="a").attrs.update(
                {"siteline_labelset": 1, "scene": plan.scene_id, "version": plan.version,
                 "parent_version": plan.parent.version, "tile_checksum": plan.tiles.checksum}
            )  # fmt: skip
    finally:
        shutil.rmtree(spill_dir, ignore_errors=True)
    created = m.changed > 0
    log.info(
        "labels of %s matched %s of %s points of scene %d; %s changed class%s%s",
        path.name, f"{m.matched:,}", f"{n_file:,}", plan.scene_id, f"{m.changed:,}",
        f" -> label set {plan.version}" if created else ": no new version",
        f" (its changes since label set {plan.base.version} merged onto {plan.parent.version})"
        if plan.merging and plan.base is not None else "",
    )  # fmt: skip
    return LabelSetImport(
        plan.scene_id, plan.version if created else plan.parent.version, plan.parent.version,
        uri if created else "", path.name, sha, n_file, m.matched, m.unmatched, m.duplicated, m.untouched,
        m.changed, m.changes, m.histogram,
        "position+gps_time+return_number" if has_time else "position+return_number",
        time.perf_counter() - t0, created, note, max_unmatched,
        plan.base.version if plan.merging and plan.base is not None else None,
    )  # fmt: skip
