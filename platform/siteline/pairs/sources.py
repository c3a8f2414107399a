"""Scene geometry for view generation, served from the tile store."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from siteline.camera.pinhole import Camera
from siteline.tiles.reader import SceneTiles, ViewNodes, node_positions
from siteline.views.sources import ArrayPointSource, ProbePoints, nearest_within

# the coarse copy of the solid geometry that overhead checks use, spacing in metres (its size grows
# with the site's area, not its density)
COARSE_M = 0.25
# a scene of at most this many points is read once into memory (13 bytes a point: float32
# site-local xyz and two flags) and every probe judged from there
MEMORY_POINTS = 25_000_000
# ... and one of at most this many gives every probe all its points (the renderer culls them): no
# level of detail to work out per probe, which at this size costs more than drawing them
WHOLE_POINTS = 1_000_000


@dataclass(frozen=True)
class _Held:
    """A scene held in memory, its tiles one after another in sorted order, each in store order:
    xyz (N, 3) float32 site-local metres, ``draw`` (N,) bool (not a skipped class), ``kept`` (N,)
    bool (not an ignored class), ``spacing`` (N,) float32 its tile's own spacing (metres), and
    ``node_start`` (K,) where each node of ``SceneTiles.all_nodes`` begins."""

    xyz: np.ndarray
    draw: np.ndarray
    kept: np.ndarray
    spacing: np.ndarray
    node_start: np.ndarray


def solid_points_near(
    scene: SceneTiles, centers: np.ndarray, radius_m: float, skip_classes: np.ndarray
) -> tuple[np.ndarray, int]:
    """The full-density points of ``scene`` that may lie within ``radius_m`` of ``centers`` ((M, 3)
    site-local metres; :meth:`SceneTiles.points_near`), those of ``skip_classes`` left out, as (N, 3)
    float64, and how many points were read for them."""
    near = scene.points_near(centers, radius_m, ("class",))
    return near.xyz_m[~np.isin(near.attributes["class"], skip_classes)], near.stats.points_read


def nearest_point(
    scenes: Sequence[SceneTiles], centers: np.ndarray, radius_m: float, skip_classes: np.ndarray
) -> np.ndarray:
    """(M,) exact distance in metres from each of ``centers`` ((M, 3) site-local) to the nearest
    full-density point of any of ``scenes`` (``skip_classes`` left out), inf where none lies within
    ``radius_m``."""
    q = np.atleast_2d(np.asarray(centers, dtype=np.float64))
    best = np.full(len(q), np.inf)
    for scene in scenes:
        solid, _ = solid_points_near(scene, q, radius_m, skip_classes)
        if len(solid):
            best = np.minimum(best, nearest_within(cKDTree(solid), q, radius_m))
    return best


class TilePointSource:
    """A :class:`siteline.views.sources.PointSource` over a tiled scene for view generation, which renders
    hundreds of probes per real camera. Each probe draws what its render needs: the nodes its
    frustum meets, at the spacing its own render scale and ``point_size_px`` need (``lod_factor``:
    ``SceneTiles.levels_for_view``; the probes must render with the same point size), with each
    point's spacing (world splats) and whether its class is kept (not ``ignored_classes``).

    A scene of at most ``memory_points`` is read once, whole, and each probe takes its nodes'
    prefixes from memory (one of at most :data:`WHOLE_POINTS` gives every probe all its points, with
    each tile's own spacing), so view generation reads the scene once whatever the candidates. A
    larger one is read per batch: the probes of one parent camera together (:meth:`prefetch`), per node the
    longest prefix any of them needs, once, so a batch reads about its frusta's union once.
    Clearance is measured exactly, on the full-density points of this scene and of ``others`` (the
    pair's earlier scene) near each camera (:meth:`SceneTiles.points_near`: nothing is read for a
    camera no node comes near); overhead checks use a coarse copy (:data:`COARSE_M`) of the solid
    geometry. Airborne snow and noise (``skip_classes``) are left out of all of it."""

    def __init__(
        self,
        tiles: SceneTiles,
        skip_classes: np.ndarray,
        ignored_classes: np.ndarray | None = None,
        others: Sequence[SceneTiles] = (),
        lod_factor: float = 1.0,
        point_size_px: int = 1,
        memory_points: int = MEMORY_POINTS,
        whole_points: int = WHOLE_POINTS,
    ) -> None:
        self.tiles = tiles
        self.others = tuple(others)
        self.skip = np.asarray(skip_classes, dtype=np.uint8)
        self.ignored = np.asarray(ignored_classes if ignored_classes is not None else [], dtype=np.uint8)
        self.lod_factor = lod_factor
        self.point_size_px = point_size_px
        self.points_read = 0
        self.reads = 0
        self.probes = 0
        self._held: _Held | None = None
        self._whole: ProbePoints | None = None
        if tiles.point_count <= memory_points:
            self._held = self._hold()
            self._coarse = ArrayPointSource(
                self._from_memory(self._held, *self._coarse_selection(COARSE_M)).xyz
            )
            if tiles.point_count <= min(memory_points, whole_points):
                h = self._held
                self._whole = ProbePoints(h.xyz[h.draw], h.spacing[h.draw], h.kept[h.draw])
        else:
            read = tiles.points(resolution=COARSE_M, attributes=("class",))
            self.points_read += read.stats.points_read
            self.reads += 1
            self._coarse = ArrayPointSource(
                read.xyz_m[~np.isin(read.attributes["class"], self.skip)].astype(np.float32)
            )
        self._batch: _Batch | None = None

    @property
    def in_memory(self) -> bool:
        """Whether the whole scene is held in memory."""
        return self._held is not None

    def _hold(self) -> _Held:
        """Every tile's points, read once."""
        xyz, cls, spacing, offset = [], [], [], {}
        at = 0
        for tile in self.tiles.all_nodes.tiles:
            out = self.tiles.read_tile(tile, ("class",))
            offset[tile] = at
            at += len(out.xyz_m)
            xyz.append(out.xyz_m.astype(np.float32))
            cls.append(out.attributes["class"])
            spacing.append(np.full(len(out.xyz_m), self.tiles.native_spacing[tile], np.float32))
            self.points_read += out.stats.points_read
        self.reads += 1
        a = self.tiles.all_nodes
        c = np.concatenate(cls) if cls else np.zeros(0, np.uint8)
        starts = (
            np.array([offset[t] for t in a.tiles], np.int64)[a.tile] + a.start
            if len(a.tile)
            else np.zeros(0, np.int64)
        )
        return _Held(
            np.concatenate(xyz) if xyz else np.zeros((0, 3), np.float32), ~np.isin(c, self.skip), ~np.isin(c, self.ignored),
            np.concatenate(spacing) if spacing else np.zeros(0, np.float32), starts,
        )  # fmt: skip

    def _coarse_selection(self, resolution_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every node's prefix that gives ``resolution_m`` spacing (as ``SceneTiles.points``): the
        nodes (positions into ``all_nodes``), how many points of each, their spacing."""
        rows = np.arange(len(self.tiles.all_nodes.lo))
        take = self.tiles.takes(rows, np.full(len(rows), resolution_m))
        keep = take > 0
        return rows[keep], take[keep], np.full(int(keep.sum()), resolution_m)

    def _from_memory(
        self,
        held: _Held,
        nodes: np.ndarray,
        take: np.ndarray,
        spacing: np.ndarray,
        planes: np.ndarray | None = None,
    ) -> ProbePoints:
        """The first ``take`` points of ``nodes`` (positions into ``all_nodes``) from the scene held in
        memory (skipped classes left out), each with the larger of ``spacing`` (its node's) and its
        tile's own, inside ``planes`` when given."""
        idx = node_positions(held.node_start[nodes], take)
        sp = np.maximum(np.repeat(spacing, take).astype(np.float32), held.spacing[idx])
        idx_draw = held.draw[idx]
        idx, sp = idx[idx_draw], sp[idx_draw]
        xyz = held.xyz[idx]
        if planes is not None and len(xyz):
            inside = np.all(
                xyz @ planes[:, :3].T.astype(np.float32) + planes[:, 3].astype(np.float32) >= 0, axis=1
            )
            idx, xyz, sp = idx[inside], xyz[inside], sp[inside]
        return ProbePoints(xyz, sp, held.kept[idx])

    def _spacing_px(self) -> float:
        return self.lod_factor * self.point_size_px / 2

    def prefetch(self, cameras: Sequence[Camera], scale: float) -> None:
        """Read once what the probes of ``cameras`` at ``scale`` need (replacing the last batch); a
        scene held in memory needs no batch."""
        self._batch = None
        if len(cameras) < 2 or self._held is not None:
            return
        merged: dict[str, np.ndarray] = {}
        chosen_by: dict[Camera, ViewNodes] = {}
        for cam in cameras:
            chosen_by[cam] = view = self.tiles.levels_for_view(cam, scale, self._spacing_px())
            for tile, (sel, take) in view.selection.items():
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
        cls = out.attributes["class"]
        self._batch = _Batch(scale, dict(zip(tiles, base[:-1].tolist(), strict=True)), int(base[-1]),
                             out.xyz_m, node, rank, ~np.isin(cls, self.skip), ~np.isin(cls, self.ignored),
                             chosen_by)  # fmt: skip

    def points_for_view(self, camera: Camera, scale: float) -> ProbePoints:
        """The points a probe of ``camera`` at ``scale`` draws, with their spacing and whether their
        class is kept: from memory, from the prefetched batch when it covers this probe's tiles,
        else read."""
        self.probes += 1
        if self._whole is not None:  # the renderer culls what the frustum leaves out
            return self._whole
        if self._held is not None:
            nodes, take, spacing, planes = self.tiles.view_nodes(camera, scale, self._spacing_px())
            return self._from_memory(self._held, nodes, take, spacing, planes)
        b = self._batch
        known = b.selections.get(camera) if b is not None and b.scale == scale else None
        view = known or self.tiles.levels_for_view(camera, scale, self._spacing_px())
        if b is not None and b.scale == scale and all(t in b.offset for t in view.selection):
            take = np.zeros(b.nodes, np.int64)
            spacing = np.zeros(b.nodes, np.float32)
            for tile, (sel, n) in view.selection.items():
                take[b.offset[tile] + sel] = n
                spacing[b.offset[tile] + sel] = view.spacing_m[tile]
            mine = (b.rank < take[b.node]) & b.draw
            xyz = b.xyz[mine]
            planes = view.planes
            inside = np.all(xyz @ planes[:, :3].T + planes[:, 3] >= 0, axis=1) if len(xyz) else mine[:0]
            chosen = np.flatnonzero(mine)[inside]
            return ProbePoints(xyz[inside].astype(np.float32), spacing[b.node[chosen]], b.kept[chosen])
        out = self.tiles.read_nodes(view.selection, ("class",))
        self.points_read += out.stats.points_read
        self.reads += 1
        cls = out.attributes["class"]
        spacing = self.tiles.spacing_of(view)
        planes = view.planes
        keep = ~np.isin(cls, self.skip)
        if len(out.xyz_m):
            keep &= np.all(out.xyz_m @ planes[:, :3].T + planes[:, 3] >= 0, axis=1)
        return ProbePoints(
            out.xyz_m[keep].astype(np.float32), spacing[keep], ~np.isin(cls[keep], self.ignored)
        )

    def nearest_within(self, xyz: np.ndarray, radius_m: float) -> np.ndarray:
        q = np.atleast_2d(np.asarray(xyz, dtype=np.float64))
        best = np.full(len(q), np.inf)
        for scene in (self.tiles, *self.others):
            if scene is self.tiles and self._held is not None:  # from memory
                rows = scene.nodes_near(q, radius_m)
                at = node_positions(self._held.node_start[rows], scene.all_nodes.count[rows])
                solid = self._held.xyz[at[self._held.draw[at]]]
            else:
                solid, read = solid_points_near(scene, q, radius_m, self.skip)
                self.points_read += read
                self.reads += read > 0
            if len(solid):
                best = np.minimum(best, nearest_within(cKDTree(solid), q, radius_m))
        return best

    def count_above(self, xyz: np.ndarray, radius_m: float) -> np.ndarray:
        return self._coarse.count_above(xyz, radius_m)


@dataclass(frozen=True)
class _Batch:
    """A prefetched read: its scale, each tile's first global node number and the node total, the
    points (site-local float64), each point's global node and rank in its node, which are drawn (not
    a skipped class) and kept (not an ignored class), and each probe's own nodes."""

    scale: float
    offset: dict[str, int]
    nodes: int
    xyz: np.ndarray
    node: np.ndarray
    rank: np.ndarray
    draw: np.ndarray
    kept: np.ndarray
    selections: dict[Camera, ViewNodes]
