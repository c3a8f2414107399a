"""Per-point change labels of a pair, stored beside the scenes' tile stores and aligned with them:
``<root>/<t1|t2>/tiles/<tile>/change`` holds, for each point of that scene's tile (in the tile's
level order), 0 unchanged, 1 changed or 255 ignored."""

from __future__ import annotations

import functools
import hashlib
import shutil
import time
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

import numpy as np
import zarr
from numcodecs import Zstd

from siteline.errors import LabelError
from siteline.labels.change import (
    CHANGED,
    IGNORED,
    NOT_OBSERVED,
    UNCHANGED,
    Matching,
    change_flags,
    median_spacing,
)
from siteline.labels.regions import RegionCells, RegionRule, points_near
from siteline.records.pairs import ChangeLabels, RadiusChoice
from siteline.records.tiling import TileSpec
from siteline.render.splats import surface_spacing
from siteline.tiles.layout import parse_tile_key
from siteline.tiles.reader import SceneTiles

SIDES = ("t1", "t2")
# changed points are linked into regions through touching cells of this many change radii: at 10
# points/m2 cells of 2 r keep 99.8 % of the truly changed points of the synthetic site (thin formwork
# included) where cells of r keep 97 %, and still take back 43 % of the false ones
REGION_CELL_RADII = 2.0
# a sparse surface's changed samples (farther apart than those cells link) are kept whole where its
# samples around changed: of its SPARSE_NEIGHBOURS nearest sparse samples within SPARSE_LINK of its own
# spacing (a column's two neighbours lie within one), at least three and SPARSE_CHANGED_SHARE (a
# majority and two kept chance flags on sparse walls and canopy at 1000 points/m2: docs/performance.md)
SPARSE_NEIGHBOURS = 8
SPARSE_LINK = 1.5
SPARSE_CHANGED_SHARE = 0.8
# the neighbours that vote are looked for in cells of this many metres around the candidates
SPARSE_AREA_M = 4.0


def auto_radius(
    a: SceneTiles, b: SceneTiles, multiplier: float = 2.5, max_points: int = 200_000
) -> tuple[float, RadiusChoice]:
    """``multiplier`` x the median nearest-neighbour spacing of the sparser scene (DESIGN.md §4),
    measured on the full-density points of each scene's most populated tile."""
    spacing = {}
    for name, tiles in (("t1", a), ("t2", b)):
        tile = max(tiles.by_tile, key=lambda t: tiles.prefix(t))
        spacing[name] = median_spacing(tiles.read_tile_uncached(tile, (), np.float64)[0], max_points)
    sparse = max(spacing.values())
    return multiplier * sparse, RadiusChoice(spacing, multiplier)


# a tile's points are labelled in slabs of at most this many (the rule's working memory is several
# times its points' bytes: a 20 M point tile held 2-3 GB at once)
BLOCK_POINTS = 2_000_000
# the offsets of a tile's 8 neighbours, in the order a halo joins their strips (after the tile itself)
_AROUND = tuple((dx, dy) for dx in (-1, 0, 1) for dy in (-1, 0, 1))
# whole decoded tiles kept per scene: the one being labelled
_WHOLE_TILES = 1
_STRIP_MARGIN_M = 1e-3
_ZSTD = Zstd(level=1)

_Part = tuple[np.ndarray, np.ndarray]  # (N, 3) float32 site-local xyz, (N,) classes


class _Decoded:
    """One scene's tiles decoded (float32 site-local xyz and classes) for labelling column by column:
    whole only while labelled (:data:`_WHOLE_TILES`), and otherwise as the edge strips within the
    radius that a neighbouring tile's halo takes from them (kept until no tile left to label needs
    them). A tile whose strips are wanted before it is labelled is read for them block by block, and
    read again when labelled: memory follows one tile and the strips, not the site's rows."""

    def __init__(self, tiles: SceneTiles, radius_m: float) -> None:
        self.tiles = tiles
        self.r = radius_m
        self.size = tiles.spec.tile_size_m
        self._whole: dict[tuple[int, int], _Part] = {}
        self._strips: dict[tuple[int, int], dict[tuple[int, int], _Part]] = {}
        self.keys = {parse_tile_key(t): t for t in tiles.by_tile}
        self.decodes = 0

    def _cut(self, ij: tuple[int, int], blocks: Iterable[_Part]) -> dict[tuple[int, int], _Part]:
        """The 8 strips of tile ``ij`` from its points (in blocks): what it gives the tile at -(dx, dy)
        from it (the west strip to the tile west of it...), a millimetre wider than the radius
        (float32 positions against float64 edges take every point within it; one more point beyond
        it changes no flag)."""
        x0, y0, r = ij[0] * self.size, ij[1] * self.size, self.r + _STRIP_MARGIN_M
        parts: dict[tuple[int, int], list[_Part]] = {d: [] for d in _AROUND if d != (0, 0)}
        for xyz, cls in blocks:
            x, y = xyz[:, 0], xyz[:, 1]
            side_x = {1: x <= x0 + r, -1: x >= x0 + self.size - r}
            side_y = {1: y <= y0 + r, -1: y >= y0 + self.size - r}
            for dx, dy in parts:
                sel = side_x[dx] & side_y[dy] if dx and dy else side_x[dx] if dx else side_y[dy]
                idx = np.flatnonzero(sel)
                parts[(dx, dy)].append((xyz[idx], cls[idx]))
        return {d: _join(p) for d, p in parts.items()}

    def get(self, ij: tuple[int, int]) -> _Part | None:
        """Tile ``ij`` whole (xyz, classes), None when the scene has no such tile."""
        if ij not in self.keys:
            return None
        hit = self._whole.get(ij)
        if hit is None:
            self._whole.clear()  # the tile labelled before goes first
            xyz, attrs = self.tiles.read_tile_uncached(self.keys[ij], ("class",))
            self.decodes += 1
            hit = self._whole[ij] = (xyz, attrs["class"])
            if ij not in self._strips:
                self._strips[ij] = self._cut(ij, [hit])
        return hit

    def _strip(self, ij: tuple[int, int], toward: tuple[int, int]) -> _Part | None:
        if ij not in self.keys:
            return None
        if ij not in self._strips:
            blocks = self.tiles.tile_blocks(self.keys[ij], ("class",))
            self._strips[ij] = self._cut(ij, ((xyz, attrs["class"]) for _, xyz, attrs in blocks))
            self.decodes += 1
        return self._strips[ij][toward]

    def halo(self, ij: tuple[int, int]) -> list[tuple[np.ndarray, np.ndarray]]:
        """This scene's points in the grid cell of tile ``ij`` widened by the radius, as parts (xyz,
        classes) not joined (a join would copy the tile): the tile itself and, of each of its 8
        neighbours, the strip within the radius of the shared edge or corner."""
        parts = []
        for dx, dy in _AROUND:
            got = self.get(ij) if (dx, dy) == (0, 0) else self._strip((ij[0] + dx, ij[1] + dy), (dx, dy))
            if got is not None:
                parts.append(got)
        return parts

    def release_before(self, column: int) -> None:
        """Drop the strips of columns left of ``column`` - 1 (no tile from ``column`` on needs them)."""
        for ij in [ij for ij in self._strips if ij[0] < column - 1]:
            del self._strips[ij]

    def close(self) -> None:
        """Let go of every tile and strip held."""
        self._whole.clear()
        self._strips.clear()


def _join(
    parts: list[tuple[np.ndarray, np.ndarray]], keep: list[np.ndarray] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The parts' points (xyz, classes) in one pair of arrays, each part's ``keep`` rows only when given."""
    if keep is not None:
        parts = [(xyz[k], cls[k]) for (xyz, cls), k in zip(parts, keep, strict=True)]
    if not parts:
        return np.zeros((0, 3), np.float32), np.zeros(0, np.uint8)
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def _flags_in_blocks(
    a_xyz: np.ndarray, a_cls: np.ndarray, halo: list[tuple[np.ndarray, np.ndarray]],
    rule: Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray], halo_m: float,
) -> np.ndarray:  # fmt: skip
    """``rule`` (:func:`change_flags` with its radius and tests) of a tile's points against the other
    scene's ``halo`` (its parts, :meth:`_Decoded.halo`), in slabs of at most :data:`BLOCK_POINTS`
    (along x), each against the halo's points within ``halo_m`` of the slab: a point's flag depends
    only on those (its radius, the surface test's search radius and plan cell), so the flags are the
    tile's whole, and the rule's working memory follows the slab, not the tile (20 M points at 8000/m2)."""
    n = len(a_xyz)
    if n <= BLOCK_POINTS:
        return rule(a_xyz, a_cls, *_join(halo))
    out = np.empty(n, dtype=np.uint8)
    cuts = _slab_cuts(a_xyz[:, 0], BLOCK_POINTS)
    edges = np.concatenate([[-np.inf], cuts, [np.inf]])
    theirs = [_slab_of(b[:, 0], cuts) for b, _ in halo]
    for k, idx in _slabs(a_xyz[:, 0], cuts):
        # the halo's points within halo_m of the slab's x range (all of the halo's y lies within
        # halo_m of the tile): those of the slabs that range touches, then those within it exactly
        lo, hi = edges[k] - halo_m, edges[k + 1] + halo_m
        first, last = _slab_of(np.array([lo, hi]), cuts)
        near = []
        for (b, _), of in zip(halo, theirs, strict=True):
            cand = np.flatnonzero((of >= first) & (of <= last))
            x = b[cand, 0]
            near.append(cand[(x >= lo) & (x <= hi)])
        out[idx] = rule(a_xyz[idx], a_cls[idx], *_join(halo, near))
    return out


def _slab_cuts(x: np.ndarray, size: int) -> np.ndarray:
    """Where to cut ``x`` into consecutive slabs of about ``size`` points (whole bins of a histogram
    eight times finer; a bin denser than ``size`` is a slab of its own), without sorting the tile (an
    argsort of 25 M points held 200 MB): slab k holds cuts[k - 1] <= x < cuts[k]."""
    counts, edges = np.histogram(x, bins=8 * (len(x) // size + 1))
    cuts, held = [], 0
    for k, c in enumerate(counts):
        if held and held + c > size:
            cuts.append(float(edges[k]))
            held = 0
        held += int(c)
    return np.array(cuts, np.float64)


def _slab_of(x: np.ndarray, cuts: np.ndarray) -> np.ndarray:
    """(N,) uint16: the slab of each ``x`` between ``cuts``, worked out a block at a time (one pass:
    selecting each slab by comparing every point with its ends cost a pass per slab)."""
    out = np.empty(len(x), np.uint16)
    for lo in range(0, len(x), 1 << 20):
        out[lo : lo + (1 << 20)] = np.searchsorted(cuts, x[lo : lo + (1 << 20)], side="right")
    return out


def _slabs(x: np.ndarray, cuts: np.ndarray) -> Iterator[tuple[int, np.ndarray]]:
    """Each non-empty slab of ``x`` between ``cuts`` (:func:`_slab_cuts`): its number and the indices of
    its points, every point in exactly one."""
    of = _slab_of(x, cuts)
    for k in range(len(cuts) + 1):
        idx = np.flatnonzero(of == k)
        if len(idx):
            yield k, idx


def _write_flags(group: zarr.Group, tile: str, flags: np.ndarray, spec: TileSpec) -> None:
    from zarr.codecs import BloscCodec, BloscShuffle

    arr = group.create_group(tile).create_array(
        "change",
        shape=flags.shape,
        dtype="uint8",
        chunks=(spec.chunk_points,),
        shards=(spec.shard_points,),
        compressors=BloscCodec(cname="zstd", clevel=3, shuffle=BloscShuffle.bitshuffle),
        fill_value=IGNORED,
    )
    arr[...] = flags


def _count(flags: np.ndarray, counts: dict[str, int]) -> None:
    counts["unchanged"] += int((flags == UNCHANGED).sum())
    counts["changed"] += int((flags == CHANGED).sum())
    counts["ignored"] += int((flags == IGNORED).sum())
    unseen = int((flags == NOT_OBSERVED).sum())
    if unseen:  # the adaptive rule's (stores of the other rules keep the three counts they had)
        counts["not_observed"] = counts.get("not_observed", 0) + unseen


def write_labels(
    t1: SceneTiles,
    t2: SceneTiles,
    radius_m: float,
    ignored: np.ndarray,
    out: Path,
    geometric: np.ndarray | None = None,
    matching: Matching = Matching(),
    regions: RegionRule = RegionRule(),
) -> ChangeLabels:
    """Compute both directions in one pass over the site grid (each tile of each scene against the
    other scene's points in the tile's grid cell widened by ``radius_m``, or by the surface test's
    search radius) into the new Zarr group ``out`` (removed again on an error; publish it through
    ``siteline.stores.Store.publish`` for all-or-nothing). Tiles are decoded whole only while they
    are labelled, and as edge strips for their neighbours' halos (:class:`_Decoded`): a tile of the
    next column is decoded twice, and memory stays at a few tiles and the strips whatever the site. ``ignored``, ``geometric`` and ``matching``: the rule
    (siteline.labels.change.change_flags); then changed regions of fewer than ``regions.min_points``
    points are taken back to unchanged, each scene's changed points linked across its whole grid
    (siteline.labels.regions, linked through cells of REGION_CELL_RADII x r); with ``regions.sparse``
    the changed samples of a surface sparser than those cells are kept whole where most of its
    samples around changed (:func:`_sparse`: a pole's samples a metre apart).
    The flags of both scenes are held (a byte a point) until written."""
    t0 = time.perf_counter()
    out = Path(out)
    if out.exists():
        raise LabelError(f"label store {out} already exists: remove it or write the labels elsewhere.")
    if t1.spec.tile_size_m != t2.spec.tile_size_m:
        raise LabelError("the two scenes are tiled on different grids: tile them again with one tile size.")
    out.parent.mkdir(parents=True, exist_ok=True)
    import zarr

    halo_m = max(radius_m, matching.surface.halo_m if matching.surface is not None else 0.0)
    try:
        root = zarr.open_group(str(out), mode="w")
        sides = {"t1": (t1, _Decoded(t1, halo_m)), "t2": (t2, _Decoded(t2, halo_m))}
        rule = functools.partial(
            change_flags,
            radius_m=radius_m,
            ignored=ignored,
            matching=matching,
            geometric=geometric,
        )
        flags_of, changed = _flag_grid(
            sides, rule, halo_m, radius_m, regions.sparse and regions.min_points > 1
        )
        taken_back = {
            side: _drop_small_regions(flags_of[side], changed[side], regions.min_points) for side in sides
        }
        counts, checksum, n_total = _write_sides(
            root, {side: tiles.spec for side, (tiles, _) in sides.items()}, flags_of
        )
        root.attrs.update(
            {
                "radius_m": radius_m,
                "counts": counts,
                "checksum": checksum,
                "points": n_total,
                "small_regions": taken_back,
            }
        )
    except BaseException:
        shutil.rmtree(out, ignore_errors=True)
        raise
    return ChangeLabels(str(out), radius_m, counts, checksum, time.perf_counter() - t0, n_total)


def _flag_grid(
    sides: dict[str, tuple[SceneTiles, _Decoded]],
    rule: Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray],
    halo_m: float,
    radius_m: float,
    regions: bool = False,
) -> tuple[dict[str, dict[str, _Packed]], dict[str, RegionCells]]:
    """Each tile of each scene flagged against the other scene's halo, the site grid column by column
    (strips of columns behind let go): the packed flags per side and tile, and each side's changed
    points as region cells (``regions``: with those of a sparse surface marked whole, :func:`_sparse`)."""
    other = {"t1": "t2", "t2": "t1"}
    flags_of: dict[str, dict[str, _Packed]] = {side: {} for side in sides}
    changed = {side: RegionCells(REGION_CELL_RADII * radius_m) for side in sides}
    grid = sorted(set(sides["t1"][1].keys) | set(sides["t2"][1].keys))
    for ij in grid:
        for dec in (sides["t1"][1], sides["t2"][1]):
            dec.release_before(ij[0])
        for side, (_, dec) in sides.items():
            mine = dec.get(ij)
            if mine is None:
                continue
            flags = _flags_in_blocks(mine[0], mine[1], sides[other[side]][1].halo(ij), rule, halo_m)
            flags_of[side][dec.keys[ij]] = _Packed(flags)
            now = flags == CHANGED
            whole = (
                _sparse(mine[0], now, sides[side][0].native_spacing[dec.keys[ij]], changed[side].cell_m)
                if regions
                else None
            )
            changed[side].add(mine[0][now], whole)
    for _, dec in sides.values():
        dec.close()
    return flags_of, changed


def _sparse(xyz: np.ndarray, changed: np.ndarray, spacing_m: float, cell_m: float) -> np.ndarray | None:
    """Of a tile's changed points (``changed``: (N,) bool over its points ``xyz``), those of a surface
    whose own spacing exceeds the region cell (siteline.render.splats.surface_spacing, against the
    tile's ``spacing_m``) whose sparse neighbours (the SPARSE_NEIGHBOURS nearest within SPARSE_LINK of
    its own spacing, itself included) changed too, at least three and SPARSE_CHANGED_SHARE of them: a
    pole put up, its samples a metre apart, each too far from the next to make a region, is kept
    whole; a few chance flags on a fence both flights grazed (most of its samples unchanged) are not.
    The tile's changed points are looked at first, and only the points around those on a sparse
    surface after them (most tiles hold none)."""
    from scipy.spatial import cKDTree

    if not changed.any():
        return None
    xyz32 = np.ascontiguousarray(xyz, dtype=np.float32)
    spacing = np.full(len(xyz), spacing_m, np.float32)
    moved_at = np.flatnonzero(changed)
    candidates = moved_at[surface_spacing(xyz32, spacing, moved_at) > cell_m]
    if not len(candidates):  # no sparse change: most tiles
        return None
    # the points that vote, changed or not: the sparse ones in the cells of SPARSE_AREA_M holding a
    # candidate or touching one
    around = points_near(xyz32, candidates, SPARSE_AREA_M)
    own = np.zeros(len(xyz), np.float32)
    own[around] = surface_spacing(xyz32, spacing, around)
    sparse = np.flatnonzero(own > cell_m)
    if not len(sparse):  # their own spacing, among the points around them, is within the cells
        return None
    pts = np.asarray(xyz)[sparse].astype(np.float64)
    k = min(SPARSE_NEIGHBOURS, len(sparse))
    dist, nearest = cKDTree(pts).query(pts, k=k, distance_upper_bound=float(SPARSE_LINK * own[sparse].max()))
    dist, nearest = dist.reshape(len(pts), k), nearest.reshape(len(pts), k)
    within = dist <= SPARSE_LINK * own[sparse][:, None]  # itself included
    moved = (within & changed[sparse][np.minimum(nearest, len(sparse) - 1)]).sum(axis=1)
    held = (moved >= 3) & (moved >= SPARSE_CHANGED_SHARE * within.sum(axis=1))
    keep = np.zeros(len(xyz), bool)
    keep[sparse] = changed[sparse] & held
    return keep[changed]


def _write_sides(
    root: zarr.Group, specs: dict[str, TileSpec], flags_of: dict[str, dict[str, _Packed]]
) -> tuple[dict[str, dict[str, int]], str, int]:
    """Write every tile's flags under ``root/<side>/tiles/``: the counts per side and label, the
    checksum of both sides' flags, and the points written."""
    counts = {side: {"unchanged": 0, "changed": 0, "ignored": 0} for side in flags_of}
    digests: dict[str, dict[str, str]] = {side: {} for side in flags_of}
    n_total = 0
    for side, tiles in flags_of.items():
        group = root.require_group(side).require_group("tiles")
        for tile, packed in tiles.items():
            flags = packed.unpack()
            _write_flags(group, tile, flags, specs[side])
            digests[side][tile] = hashlib.sha256(flags.tobytes()).hexdigest()
            _count(flags, counts[side])
            n_total += len(flags)
    h = {
        side: hashlib.sha256("".join(f"{t}:{d}" for t, d in sorted(dg.items())).encode()).hexdigest()
        for side, dg in digests.items()
    }
    return counts, hashlib.sha256(f"{h['t1']}:{h['t2']}".encode()).hexdigest(), n_total


class _Packed:
    """A tile's flags held compressed until written (a byte a point of both scenes was 0.39 GB at
    8000 points/m2; they are mostly one value, and zstd keeps a few per cent of it)."""

    def __init__(self, flags: np.ndarray) -> None:
        self.n = len(flags)
        self._data = _ZSTD.encode(np.ascontiguousarray(flags, np.uint8))

    def unpack(self) -> np.ndarray:
        return np.frombuffer(_ZSTD.decode(self._data), np.uint8, count=self.n).copy()

    def repack(self, flags: np.ndarray) -> None:
        self._data = _ZSTD.encode(np.ascontiguousarray(flags, np.uint8))


def _drop_small_regions(flags: dict[str, _Packed], changed: RegionCells, min_points: int) -> int:
    """Take the changed points of regions under ``min_points`` points back to unchanged in ``flags``
    (tile -> flags, in the order ``changed`` took each tile's changed points); return how many."""
    if min_points <= 1:
        return 0
    taken = 0
    for packed, small in zip(flags.values(), changed.small(min_points), strict=True):
        if not small.any():
            continue
        tile_flags = packed.unpack()
        tile_flags[np.flatnonzero(tile_flags == CHANGED)[small]] = UNCHANGED
        packed.repack(tile_flags)
        taken += int(small.sum())
    return taken
