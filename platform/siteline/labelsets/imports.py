"""Importing corrected semantic labels as a new label-set version of a scene.

The file (LAS/LAZ, typically a ``siteline scene export`` corrected in CloudCompare, DJI Modify or any
LAS editor) is streamed once into per-tile spill files, then each tile's stored points are matched to
the file's points (siteline.labelsets.match) and the tile's classes are written: the file's class
where a point matched, the previous version's elsewhere (so a region export is corrected alone). The
store is published whole and only then is the catalog row added; on any refusal nothing is left.
"""

from __future__ import annotations

import contextlib
import json
import shutil
import tempfile
import time
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import sqlalchemy as sa

from siteline.catalog import Catalog
from siteline.catalog.labelsets import add_label_set, label_sets
from siteline.catalog.models import Site
from siteline.catalog.scenes import get_scene
from siteline.catalog.sites import site_spec
from siteline.catalog.stages import completed
from siteline.config import Settings
from siteline.errors import LabelSetError, SchemaError
from siteline.hashing import sha256_file
from siteline.labelsets.compare import changes_by_class, histogram, pair_counts
from siteline.labelsets.match import match_points, point_keys
from siteline.labelsets.store import labelset_uri, open_labelled_tiles, write_tile_classes
from siteline.lasio import open_las, read_labels_vlr
from siteline.progress import Progress
from siteline.site import SiteSpec
from siteline.sitestream import file_crs, site_chunks, source_transformer
from siteline.tiles.layout import parse_tile_key, quantise, tile_index, tile_key, tile_origin_local
from siteline.tiles.reader import SceneTiles
from siteline.tiles.scene import tile_checksum

# Refuse a file when more than this fraction of its points match no stored point or match one
# already taken: an editor that keeps points never creates either, so anything above rounding
# noise means another scene, a merged or re-sampled file, or moved points.
DEFAULT_MAX_UNMATCHED = 0.001


class _Unchanged(Exception):
    """No point changed class: the store under construction is dropped."""


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


@dataclass
class ImportResult:
    """A new label-set version: where it is, and how the file's points matched the scene's.
    untouched: stored points the file does not hold (they keep the previous version's class).
    created: False when no point changed class (no version is made; ``version`` is the current one)."""

    scene_id: int
    version: int
    parent_version: int
    uri: str
    file: str
    source_sha256: str
    points_in_file: int
    matched: int
    unmatched: int
    duplicated: int
    untouched: int
    changed: int
    changes: dict[str, int] = field(default_factory=dict)
    class_histogram: dict[str, int] = field(default_factory=dict)
    key: str = ""
    seconds: float = 0.0
    created: bool = True

    def to_dict(self) -> dict:
        return asdict(self)


def read_taxonomy_map(path: Path) -> dict[int, str | int]:
    """A JSON object mapping the file's class codes to site classes (name or id):
    ``{"2": "ground", "6": "building", "64": 3}``."""
    try:
        doc = json.loads(Path(path).read_text())
    except FileNotFoundError as exc:
        raise LabelSetError(f"taxonomy map {path} does not exist.") from exc
    except ValueError as exc:
        raise LabelSetError(f"taxonomy map {path} is not JSON: {exc}") from exc
    if not isinstance(doc, dict) or not doc:
        raise LabelSetError(
            f'taxonomy map {path} must be a JSON object of code -> class, e.g. {{"2": "ground"}}.'
        )
    out: dict[int, str | int] = {}
    for code, target in doc.items():
        try:
            out[int(code)] = target
        except ValueError as exc:
            raise LabelSetError(f"taxonomy map {path}: key {code!r} is not a class code.") from exc
    return out


def _check_origin(doc: dict | None, scene_id: int, site: SiteSpec, path: Path) -> None:
    """Refuse a file whose siteline record says it was exported from another scene or site."""
    if doc is None:
        return
    if doc.get("site") != site.name or doc.get("scene") != scene_id:
        raise LabelSetError(
            f"labels file {path} was exported from scene {doc.get('scene')} of site {doc.get('site')}, "
            f"not scene {scene_id} of site {site.name}: import it into that scene. Nothing was written."
        )


def _spill(
    path: Path, scene_id: int, site: SiteSpec, tiles: SceneTiles, lut: tuple[np.ndarray, np.ndarray], spill_dir: Path,
    progress: Progress | None,
) -> tuple[int, bool, np.ndarray]:  # fmt: skip
    """Stream the file into per-tile spill files (a point within one quantum of a tile edge goes to
    both tiles); return its point count, whether it has GPS times, and the count per unknown code."""
    size, q = tiles.spec.tile_size_m, tiles.spec.quantum_m
    unknown = np.zeros(256, dtype=np.int64)
    n = 0
    with open_las(path) as reader:
        _check_origin(read_labels_vlr(reader.header, path), scene_id, site, path)
        has_time = "gps_time" in reader.header.point_format.dimension_names
        crs = file_crs(reader, path) or site.pyproj_crs  # an editor may drop the CRS: it is the export's
        tr = source_transformer(path, site, crs)
        for sc in site_chunks(path, site, tr, reader=reader, class_lut=lut):
            codes = sc.chunk.classification
            unknown += np.bincount(codes[~sc.known_code], minlength=256)
            rec = np.empty(len(sc.local), SPILL_DTYPE)
            rec["idx"] = np.arange(n, n + len(rec))
            rec["local"] = sc.local
            rec["gps_time"] = sc.chunk.gps_time if has_time else 0.0
            rec["return_number"] = sc.chunk.return_number
            rec["class"] = sc.classes
            ij = tile_index(sc.local, size)
            frac = sc.local[:, :2] / size - ij
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
            n += len(rec)
            if progress:
                progress("reading labels", len(rec), None)
    return n, has_time, unknown


def import_labels(
    catalog: Catalog,
    settings: Settings,
    scene_id: int,
    path: Path,
    taxonomy_map: dict[int, str | int] | None = None,
    note: str | None = None,
    max_unmatched: float = DEFAULT_MAX_UNMATCHED,
    progress: Progress | None = None,
    run_id: str | None = None,
) -> ImportResult:
    """Import the classes of ``path`` as the next label-set version of ``scene_id``.

    Codes are site class ids (as ``scene export`` writes them) unless ``taxonomy_map`` maps them.
    Points are matched by position in tile quanta, GPS time and return number; refused (nothing
    written) when the file is of another scene, holds unknown codes, is unreadable, or when more
    than ``max_unmatched`` of its points match nothing or match a point already taken."""
    t0 = time.perf_counter()
    started = datetime.now(UTC)
    path = Path(path)
    if not path.is_file():
        raise LabelSetError(f"labels file {path} does not exist.")
    if not 0.0 <= max_unmatched < 1.0:
        raise LabelSetError(f"max_unmatched {max_unmatched}: use a fraction in [0, 1).")
    with catalog.transaction() as s:
        scene = get_scene(s, scene_id)
        site = site_spec(s.get(Site, scene.site_id))
        tiles, parent = open_labelled_tiles(s, scene)
        version = max(r.version for r in label_sets(s, scene_id)) + 1
        tiling = tile_checksum(scene)
    try:
        lut = site.taxonomy.id_lut(taxonomy_map)
    except SchemaError as exc:
        raise LabelSetError(f"labels file {path}: {exc}") from exc
    sha = sha256_file(path)
    uri = labelset_uri(settings, scene_id, version)
    settings.store.remove(uri)  # a store a crashed import published without its row
    (settings.home / "tmp").mkdir(parents=True, exist_ok=True)
    spill_dir = Path(tempfile.mkdtemp(prefix=f"labels-scene-{scene_id}-", dir=settings.home / "tmp"))
    try:
        n_file, has_time, unknown = _spill(path, scene_id, site, tiles, lut, spill_dir, progress)
        if unknown.any():
            codes = {int(c): int(unknown[c]) for c in np.nonzero(unknown)[0]}
            hint = "map them with --taxonomy-map" if taxonomy_map is None else "add them to the taxonomy map"
            raise LabelSetError(
                f"labels file {path}: class codes {sorted(codes)} ({sum(codes.values()):,} points) are not "
                f"classes of site {site.name}'s taxonomy (ids {sorted(c.id for c in site.taxonomy.classes)}): "
                f"{hint}. Nothing was written."
            )
        if n_file == 0:
            raise LabelSetError(f"labels file {path} holds no points. Nothing was written.")
        result = None
        with contextlib.suppress(_Unchanged), settings.store.publish(uri) as work:
            result = _match_tiles(tiles, spill_dir, has_time, work, site, n_file, progress)
            bad = result["unmatched"] + result["duplicated"]
            if result["matched"] == 0 or bad > max_unmatched * n_file:
                raise LabelSetError(
                    f"labels file {path}: {result['unmatched']:,} of its {n_file:,} points match no point of "
                    f"scene {scene_id} and {result['duplicated']:,} repeat a point already matched "
                    f"({bad / n_file:.2%}, limit {max_unmatched:.2%}): is it an export of scene {scene_id}, "
                    "unmoved and not merged or resampled? Nothing was written."
                )
            if result["changed"] == 0:
                raise _Unchanged
            import zarr

            zarr.open_group(str(work), mode="a").attrs.update(
                {
                    "siteline_labelset": 1,
                    "scene": scene_id,
                    "version": version,
                    "parent_version": parent,
                    "tile_checksum": tiling,
                }
            )
    finally:
        shutil.rmtree(spill_dir, ignore_errors=True)
    key = "position+gps_time+return_number" if has_time else "position+return_number"
    created = result["changed"] > 0
    out = ImportResult(
        scene_id, version if created else parent, parent, uri if created else "", path.name, sha, n_file,
        result["matched"], result["unmatched"], result["duplicated"], result["untouched"], result["changed"],
        result["changes"], result["histogram"], key, 0.0, created,
    )  # fmt: skip
    if not created:
        out.seconds = time.perf_counter() - t0
        return out
    details = {
        k: out.to_dict()[k]
        for k in (
            "file",
            "points_in_file",
            "matched",
            "unmatched",
            "duplicated",
            "untouched",
            "changes",
            "key",
        )
    } | {"max_unmatched": max_unmatched}
    try:
        with catalog.transaction() as s:
            add_label_set(
                s, scene_id, version, uri, parent, f"import {path.name}", sha, note, out.class_histogram,
                out.changed, details,
            )  # fmt: skip
            s.add(
                completed(
                    "import_labels",
                    f"scene:{scene_id}",
                    {"file": str(path), "version": version},
                    started,
                    run_id,
                )
            )
    except sa.exc.IntegrityError as exc:
        settings.store.remove(uri)
        raise LabelSetError(
            f"scene {scene_id}: another import recorded label-set version {version} meanwhile; import "
            f"{path} again."
        ) from exc
    except BaseException:
        settings.store.remove(uri)
        raise
    out.seconds = time.perf_counter() - t0
    return out


def _match_tiles(
    tiles: SceneTiles,
    spill_dir: Path,
    has_time: bool,
    work: Path,
    site: SiteSpec,
    n_file: int,
    progress: Progress | None,
) -> dict:
    """Match every tile's stored points to its spilled file points and write the tile's classes. A
    file point near a tile edge was spilled to both tiles: once matched it is skipped in the next;
    it is a duplicate only if no tile matched it; a point spilled nowhere (no such tile) or matched
    by no tile's key is unmatched."""
    import zarr

    group = zarr.open_group(str(work), mode="w")
    spec = tiles.spec
    taken_edge: list[np.ndarray] = []
    dup_edge: list[np.ndarray] = []
    matched = untouched = dup_inner = 0
    counts = np.zeros((256, 256), dtype=np.int64)
    keys = sorted(tiles.by_tile)
    for tile in keys:
        i, j = parse_tile_key(tile)
        origin = tile_origin_local(i, j, spec.tile_size_m)
        data = tiles.read({tile: tiles.prefix(tile)}, ("gps_time", "return_number", "class"))
        stored = point_keys(
            quantise(data["xyz_m"], origin, spec.quantum_m),
            data["gps_time"] if has_time else None,
            data["return_number"],
        )
        spill = spill_dir / f"{tile}.bin"
        inc = np.fromfile(spill, dtype=SPILL_DTYPE) if spill.exists() else np.zeros(0, SPILL_DTYPE)
        if taken_edge and inc["edge"].any():
            inc = inc[~(inc["edge"] & np.isin(inc["idx"], np.concatenate(taken_edge)))]
        incoming = point_keys(
            quantise(inc["local"], origin, spec.quantum_m),
            inc["gps_time"] if has_time else None,
            inc["return_number"],
        )
        m = match_points(stored, incoming)
        new = data["class"].copy()
        new[m.stored] = inc["class"][m.incoming]
        counts += pair_counts(data["class"], new)
        write_tile_classes(group, tile, new, spec)
        hit = inc[m.incoming]
        taken_edge.append(hit["idx"][hit["edge"]])
        dup = inc[m.duplicated]
        dup_edge.append(dup["idx"][dup["edge"]])
        dup_inner += int((~dup["edge"]).sum())
        matched += len(m.stored)
        untouched += len(stored) - len(m.stored)
        if progress:
            progress("matching tiles", 1, len(keys))
    taken = np.concatenate(taken_edge) if taken_edge else np.zeros(0, np.int64)
    dup_edge_idx = np.concatenate(dup_edge) if dup_edge else np.zeros(0, np.int64)
    duplicated = dup_inner + len(np.setdiff1d(dup_edge_idx, taken))
    return {
        "matched": matched,
        "unmatched": n_file - matched - duplicated,
        "duplicated": duplicated,
        "untouched": untouched,
        "changed": int(counts.sum() - np.trace(counts)),
        "changes": changes_by_class(counts, site.taxonomy),
        "histogram": histogram(counts, site.taxonomy),
    }
