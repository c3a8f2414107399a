"""Per-point change labels of a pair, stored beside the scenes' tile stores and aligned with them:
``<root>/<t1|t2>/tiles/<tile>/change`` holds, for each point of that scene's tile (in the tile's
level order), 0 unchanged, 1 changed or 255 ignored."""

from __future__ import annotations

import hashlib
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from siteline import stores
from siteline.errors import LabelError
from siteline.labels.change import CHANGED, IGNORED, UNCHANGED, change_flags, median_spacing
from siteline.tiles.reader import SceneTiles

SIDES = ("t1", "t2")


@dataclass
class LabelResult:
    uri: str
    radius_m: float
    counts: dict[str, dict[str, int]]
    checksum: str
    seconds: float
    points: int

    def to_dict(self) -> dict:
        return self.__dict__.copy()


def auto_radius(
    a: SceneTiles, b: SceneTiles, multiplier: float = 2.5, max_points: int = 200_000
) -> tuple[float, dict]:
    """``multiplier`` x the median nearest-neighbour spacing of the sparser scene (DESIGN.md §4),
    measured on the full-density points of each scene's most populated tile."""
    spacing = {}
    for name, tiles in (("t1", a), ("t2", b)):
        tile = max(tiles.by_tile, key=lambda t: tiles.prefix(t, None))
        pts = tiles.read({tile: tiles.prefix(tile, None)}, ())["xyz"]
        spacing[name] = median_spacing(pts, max_points)
    sparse = max(spacing.values())
    return multiplier * sparse, {"median_spacing_m": spacing, "multiplier": multiplier}


def _label_side(
    src: SceneTiles, other: SceneTiles, radius_m: float, ignored: np.ndarray, out_root: str, side: str
) -> tuple[dict[str, int], str, int]:
    import zarr
    from zarr.codecs import BloscCodec, BloscShuffle

    group = zarr.open_group(out_root, mode="a").require_group(side).require_group("tiles")
    counts = {"unchanged": 0, "changed": 0, "ignored": 0}
    digest = hashlib.sha256()
    n_total = 0
    for tile in sorted(src.by_tile):
        mine = src.read({tile: src.prefix(tile, None)}, ("class",))
        lo = mine["xyz"].min(axis=0) - radius_m
        hi = mine["xyz"].max(axis=0) + radius_m
        theirs = other.points(bounds=(*lo, *hi), attributes=("class",))  # the tile plus a halo of r
        flags = change_flags(mine["xyz"], mine["class"], theirs["xyz"], theirs["class"], radius_m, ignored)
        arr = group.create_group(tile).create_array(
            "change",
            shape=flags.shape,
            dtype="uint8",
            chunks=(src.spec.chunk_points,),
            shards=(src.spec.shard_points,),
            compressors=BloscCodec(cname="zstd", clevel=3, shuffle=BloscShuffle.bitshuffle),
            fill_value=IGNORED,
        )
        arr[...] = flags
        digest.update(tile.encode())
        digest.update(flags.tobytes())
        counts["unchanged"] += int((flags == UNCHANGED).sum())
        counts["changed"] += int((flags == CHANGED).sum())
        counts["ignored"] += int((flags == IGNORED).sum())
        n_total += len(flags)
    return counts, digest.hexdigest(), n_total


def write_labels(
    t1: SceneTiles, t2: SceneTiles, radius_m: float, ignored: np.ndarray, out: Path
) -> LabelResult:
    """Compute both directions tile by tile (each tile against the other scene's points within the
    tile's bounds plus a halo of ``radius_m``) into the new Zarr group ``out`` (removed again on an
    error; publish it through ``siteline.stores.Store.publish`` for all-or-nothing)."""
    t0 = time.perf_counter()
    out = Path(out)
    if out.exists():
        raise LabelError(f"label store {out} already exists: remove it or write the labels elsewhere.")
    out.parent.mkdir(parents=True, exist_ok=True)
    import zarr

    try:
        root = zarr.open_group(str(out), mode="w")
        c1, h1, n1 = _label_side(t1, t2, radius_m, ignored, str(out), "t1")
        c2, h2, n2 = _label_side(t2, t1, radius_m, ignored, str(out), "t2")
        checksum = hashlib.sha256(f"{h1}:{h2}".encode()).hexdigest()
        root.attrs.update({"radius_m": radius_m, "counts": {"t1": c1, "t2": c2}, "checksum": checksum})
    except BaseException:
        shutil.rmtree(out, ignore_errors=True)
        raise
    return LabelResult(str(out), radius_m, {"t1": c1, "t2": c2}, checksum, time.perf_counter() - t0, n1 + n2)


def attach_labels(tiles: SceneTiles, label_uri: str, side: str) -> SceneTiles:
    """Let ``tiles`` read the attribute ``change`` from a pair's label store for scene ``side``."""
    tiles.attach("change", stores.join(str(label_uri), side))
    return tiles
