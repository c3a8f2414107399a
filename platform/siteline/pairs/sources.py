"""Scene geometry for view generation, served from the tile store."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from siteline.cameras import Camera
from siteline.tiles.reader import SceneTiles, Selection
from siteline.views.sources import ArrayPointSource


class TilePointSource:
    """A :class:`siteline.views.PointSource` over a tiled scene for view generation, which renders
    hundreds of probes per real camera. Each probe reads only what it needs: the tiles its frustum
    meets, at the spacing its own render scale and ``point_size_px`` need (``lod_factor``:
    ``SceneTiles.points_for_view``; the probes must render with the same point size), so a probe's
    cost grows with its pixels, not with the scene's density; the tile reader's cache keeps the tiles a pair's probes share.
    The probes of one parent camera are read together (:meth:`prefetch`): per node, the longest
    prefix any of them needs, once; each probe then takes its own prefix of every node from that
    batch, the same points a read of its own gives, so a batch reads about its frusta's union once.
    Clearance and overhead checks use a coarse copy (``coarse_m``) of the solid geometry, whose size
    grows with the site's area, not its density. Airborne snow and noise are left out of both."""

    def __init__(
        self,
        tiles: SceneTiles,
        skip_classes: np.ndarray,
        coarse_m: float = 0.25,
        lod_factor: float = 1.0,
        point_size_px: int = 1,
    ) -> None:
        self.tiles = tiles
        self.skip = np.asarray(skip_classes, dtype=np.uint8)
        self.lod_factor = lod_factor
        self.point_size_px = point_size_px
        self.points_read = 0
        self.reads = 0
        coarse = tiles.points(resolution=coarse_m, attributes=("class",))
        keep = ~np.isin(coarse.attributes["class"], self.skip)
        self._coarse = ArrayPointSource(coarse.xyz_m[keep].astype(np.float32))
        self._batch: _Batch | None = None

    def _spacing_px(self) -> float:
        return self.lod_factor * self.point_size_px / 2

    def prefetch(self, cameras: Sequence[Camera], scale: float) -> None:
        """Read once what the probes of ``cameras`` at ``scale`` need (replacing the last batch)."""
        self._batch = None
        if len(cameras) < 2:
            return
        merged: dict[str, np.ndarray] = {}
        chosen_by: dict[Camera, tuple[Selection, np.ndarray]] = {}
        for cam in cameras:
            chosen_by[cam] = selection, _ = self.tiles.levels_for_view(cam, scale, self._spacing_px())
            for tile, (sel, take) in selection.items():
                most = merged.setdefault(tile, np.zeros(len(self.tiles.by_tile[tile]), np.int64))
                np.maximum.at(most, sel, take)
        tiles = sorted(merged)
        chosen = {t: (np.flatnonzero(merged[t]), merged[t][merged[t] > 0]) for t in tiles}
        out = self.tiles.read_nodes({t: c for t, c in chosen.items() if len(c[0])}, ("class",))
        self.points_read += out.stats.points_read
        self.reads += 1
        base = np.cumsum([0] + [len(self.tiles.by_tile[t]) for t in tiles])
        node = np.concatenate([np.repeat(base[k] + chosen[t][0], chosen[t][1]) for k, t in enumerate(tiles)])
        rank = np.concatenate([np.arange(n) for t in tiles for n in chosen[t][1]]) if len(node) else node
        keep = ~np.isin(out.attributes["class"], self.skip)
        self._batch = _Batch(scale, dict(zip(tiles, base[:-1].tolist(), strict=True)), int(base[-1]),
                             out.xyz_m, node, rank, keep, chosen_by)  # fmt: skip

    def points_for_view(self, camera: Camera, scale: float) -> np.ndarray:
        """(N, 3) float32 site-local metres: the points a probe of ``camera`` at ``scale`` draws (from
        the prefetched batch when it covers this probe's tiles)."""
        b = self._batch
        if b is not None and b.scale == scale:
            known = b.selections.get(camera)
            selection, planes = known or self.tiles.levels_for_view(camera, scale, self._spacing_px())
            if all(t in b.offset for t in selection):
                take = np.zeros(b.nodes, np.int64)
                for tile, (sel, n) in selection.items():
                    take[b.offset[tile] + sel] = n
                mine = (b.rank < take[b.node]) & b.keep
                xyz = b.xyz[mine]
                inside = np.all(xyz @ planes[:, :3].T + planes[:, 3] >= 0, axis=1) if len(xyz) else mine[:0]
                return xyz[inside].astype(np.float32)
        out = self.tiles.points_for_view(
            camera, scale, attributes=("class",), lod_factor=self.lod_factor, point_size_px=self.point_size_px
        )
        self.points_read += out.stats.points_read
        self.reads += 1
        return out.xyz_m[~np.isin(out.attributes["class"], self.skip)].astype(np.float32)

    def nearest_distance(self, xyz: np.ndarray) -> np.ndarray:
        return self._coarse.nearest_distance(xyz)

    def count_above(self, xyz: np.ndarray, radius_m: float) -> np.ndarray:
        return self._coarse.count_above(xyz, radius_m)


@dataclass(frozen=True)
class _Batch:
    """A prefetched read: its scale, each tile's first global node number and the node total, the
    points (site-local float64), each point's global node and rank in its node, which are kept
    (not a skipped class), and each probe's own node selection and frustum planes."""

    scale: float
    offset: dict[str, int]
    nodes: int
    xyz: np.ndarray
    node: np.ndarray
    rank: np.ndarray
    keep: np.ndarray
    selections: dict[Camera, tuple[Selection, np.ndarray]]
