"""What the 3D pair viewer draws: both scenes' points at a level of detail under a point budget,
cut into chunks of nodes that are read and sent one at a time, with each point's change label,
class and colour; and the release's synthetic cameras as frusta (all site-local metres)."""

from __future__ import annotations

import math
import struct
import threading
from dataclasses import dataclass, field

import numpy as np

from siteline.camera.pinhole import Camera
from siteline.pairs.render import LabelledPair
from siteline.records.pairs import ColourPlan
from siteline.records.release import ReleaseItem
from siteline.schema import JSON
from siteline.site.taxonomy import Taxonomy
from siteline.tiles.reader import SceneTiles

# points drawn of both scenes together, by default: a few million keep a laptop's WebGL smooth
DEFAULT_BUDGET = 3_000_000
# about this many points per chunk (one request, one WebGL buffer): ~1.2 MB
CHUNK_POINTS = 65_536
# a chunk: uint32 n, then n x float32 xyz (metres from the plan's centre), uint8 change code,
# uint8 class, uint8 rgb x 3
HEADER = struct.Struct("<I")


@dataclass(frozen=True)
class CloudChunk:
    """A part of one scene the viewer fetches at once: nodes ``nodes`` (indices into
    ``SceneTiles.by_tile[tile]``, ascending) of ``tile``, the first ``take`` points of each."""

    tile: str
    nodes: np.ndarray
    take: np.ndarray

    @property
    def points(self) -> int:
        return int(self.take.sum())


def budget_takes(tiles: SceneTiles, budget: int) -> tuple[np.ndarray, int]:
    """Per node of ``tiles.all_nodes``, how many of its points (a prefix: the coarse levels first)
    fit a budget of ``budget`` points over the scene, and the deepest whole level: every level down
    to it whole, then an even share of each node's next level (in a store whose node prefixes span
    their nodes, a share spread over the node; else the next level is left out)."""
    below = tiles.all_nodes.below
    if not len(below):
        return np.zeros(0, np.int64), 0
    totals = below.sum(axis=0)  # totals[L]: the scene's points at levels under L
    whole = int(np.searchsorted(totals, budget, side="right")) - 1  # levels under `whole` fit
    if whole >= below.shape[1] - 1:
        return below[:, -1].copy(), below.shape[1] - 2
    take = below[:, whole].copy()
    if tiles.spec.partial_levels and whole >= 0:
        share = (budget - totals[whole]) / max(int(totals[whole + 1] - totals[whole]), 1)
        take += np.floor(share * (below[:, whole + 1] - below[:, whole])).astype(np.int64)
    return take, max(whole - 1, 0)


def chunk_plan(tiles: SceneTiles, take: np.ndarray, chunk_points: int = CHUNK_POINTS) -> list[CloudChunk]:
    """The first ``take`` points of each node of ``tiles.all_nodes`` (:func:`budget_takes`) as chunks
    of at most about ``chunk_points``, each within one tile, tile by tile."""
    a = tiles.all_nodes
    chunks: list[CloudChunk] = []
    for t, tile in enumerate(a.tiles):
        rows = np.flatnonzero((a.tile == t) & (take > 0))
        if not len(rows):
            continue
        sizes = take[rows]
        group = np.cumsum(sizes) // chunk_points
        group = np.concatenate([[0], np.cumsum(np.diff(group) > 0)])
        for g in np.unique(group):
            sel = rows[group == g]
            order = np.argsort(a.index[sel], kind="stable")
            chunks.append(CloudChunk(tile, a.index[sel][order], take[sel][order]))
    return chunks


def encode_chunk(
    tiles: SceneTiles,
    chunk: CloudChunk,
    side: int,
    colour: ColourPlan,
    centre: np.ndarray,
    floor_z: float = 0.0,
) -> bytes:
    """Read ``chunk`` of scene ``side`` (1 or 2; ``tiles`` reads ``change`` and ``class``) and pack
    it as :data:`HEADER` describes: positions in float32 metres from ``centre`` (site-local, so
    float32 keeps millimetres whatever the site's coordinates), the change code, class and colour
    (a height colour, whose ground model the viewer lacks, from the scenes' lowest z, ``floor_z``)."""
    source = colour.attribute
    names = ("change", "class", *((source,) if source else ()))
    pts = tiles.read_nodes({chunk.tile: (chunk.nodes, chunk.take)}, names)
    values = pts.attributes.get(source) if source else None
    if colour.source == "height":
        values = pts.xyz_m[:, 2] - floor_z
    rgb = colour.colours(side, pts.xyz_m, values)
    xyz = (pts.xyz_m - centre).astype("<f4")
    n = len(xyz)
    return b"".join((
        HEADER.pack(n), xyz.tobytes(), pts.attributes["change"].astype(np.uint8).tobytes(),
        pts.attributes["class"].astype(np.uint8).tobytes(), np.ascontiguousarray(rgb, dtype=np.uint8).tobytes(),
    ))  # fmt: skip


def decode_chunk(data: bytes) -> dict[str, np.ndarray]:
    """The arrays of an :func:`encode_chunk` payload (what the viewer's script reads)."""
    (n,) = HEADER.unpack_from(data)
    at = HEADER.size
    xyz = np.frombuffer(data, "<f4", n * 3, at).reshape(n, 3)
    at += 12 * n
    change = np.frombuffer(data, np.uint8, n, at)
    cls = np.frombuffer(data, np.uint8, n, at + n)
    rgb = np.frombuffer(data, np.uint8, 3 * n, at + 2 * n).reshape(n, 3)
    if at + 5 * n != len(data):
        raise ValueError(f"a chunk of {n} points must be {at + 5 * n} bytes, not {len(data)}")
    return {"xyz": xyz, "change": change, "class": cls, "rgb": rgb}


def frustum(camera: Camera, depth_m: float) -> list[list[float]]:
    """The camera's centre and its image's four corners (top-left, top-right, bottom-right,
    bottom-left) at ``depth_m`` metres in front of it, site-local metres (5 x 3)."""
    w, h = camera.width, camera.height
    pix = np.array([[0, 0, 1], [w, 0, 1], [w, h, 1], [0, h, 1]], dtype=np.float64)
    rays = (np.linalg.inv(camera.K) @ pix.T).T * depth_m  # camera axes, z = depth
    corners = (camera.R.T @ (rays - camera.t).T).T
    return [[float(v) for v in p] for p in (camera.center, *corners)]


@dataclass(frozen=True)
class PairCloud:
    """A released pair opened for the viewer: both scenes reading their change labels and classes
    (``scenes``), the pair's colour, the site's taxonomy, and the release's items of the pair
    (their manifest records: id, split, view, strategy, camera)."""

    pair_id: int
    scenes: LabelledPair
    colour: ColourPlan
    taxonomy: Taxonomy
    items: tuple[ReleaseItem, ...]

    def plan(self, budget: int = DEFAULT_BUDGET) -> CloudPlan:
        """What the viewer fetches for a budget of ``budget`` points over both scenes."""
        t1, t2 = self.scenes.t1, self.scenes.t2
        lo = np.min([t.all_nodes.lo.min(axis=0) for t in (t1, t2) if len(t.all_nodes.lo)], axis=0)
        hi = np.max([t.all_nodes.hi.max(axis=0) for t in (t1, t2) if len(t.all_nodes.hi)], axis=0)
        (take1, level1), (take2, level2) = (budget_takes(t, budget // 2) for t in (t1, t2))
        return CloudPlan(
            self,
            (chunk_plan(t1, take1), chunk_plan(t2, take2)),
            (lo + hi) / 2,
            hi - lo,
            (level1, level2),
            budget,
        )

    def side(self, side: int) -> SceneTiles:
        return self.scenes.t1 if side == 1 else self.scenes.t2


@dataclass(frozen=True)
class CloudPlan:
    """The chunks of each scene (``chunks[0]``: t1) under a budget, the middle of the two scenes'
    bounds (site-local metres; positions are sent from it) and their extent, the deepest whole
    level drawn of each, and the point budget they were chosen for."""

    cloud: PairCloud
    chunks: tuple[list[CloudChunk], list[CloudChunk]]
    centre: np.ndarray
    extent: np.ndarray
    levels: tuple[int, int]
    budget: int
    # a scene's reader keeps a cache of decoded chunks: one read of it at a time (a page asks for several)
    _reading: tuple[threading.Lock, threading.Lock] = field(
        default_factory=lambda: (threading.Lock(), threading.Lock()), repr=False, compare=False
    )

    def chunk(self, side: int, k: int) -> bytes:
        """Chunk ``k`` of scene ``side`` (1 or 2), packed (:func:`encode_chunk`); IndexError when none.
        Safe to call from several threads."""
        if side not in (1, 2) or not 0 <= k < len(self.chunks[side - 1]):
            raise IndexError(f"scene t{side} has no chunk {k}")
        with self._reading[side - 1]:
            floor = float(self.centre[2] - self.extent[2] / 2)
            return encode_chunk(
                self.cloud.side(side), self.chunks[side - 1][k], side, self.cloud.colour, self.centre, floor
            )

    def to_dict(self, browser: str | None) -> dict[str, JSON]:
        """The viewer's plan (JSON): chunk counts and sizes, the centre, the classes, and each camera
        of the pair's items as a frustum relative to the centre (depth: 6 % of the scenes' extent),
        with the URL of its item in the release browser (``browser``: the page's URL; None: none)."""
        depth = max(float(np.linalg.norm(self.extent[:2])) * 0.06, 1.0)
        cams = []
        for it in self.cloud.items:
            if not it.camera:
                continue
            pts = np.asarray(frustum(Camera.from_dict(dict(it.camera), f"item {it.id}"), depth)) - self.centre
            cams.append({
                "item": it.id, "split": it.split, "view": it.view, "strategy": it.strategy,
                "points": np.round(pts, 4).tolist(), "browser": f"{browser}#item={it.id}" if browser else None,
            })  # fmt: skip
        return {
            "pair": self.cloud.pair_id,
            "centre": [float(v) for v in self.centre],
            "extent": [float(v) for v in self.extent],
            "chunks": {f"t{s + 1}": [c.points for c in self.chunks[s]] for s in (0, 1)},
            "points": {f"t{s + 1}": sum(c.points for c in self.chunks[s]) for s in (0, 1)},
            "scene_points": {"t1": self.cloud.scenes.t1.point_count, "t2": self.cloud.scenes.t2.point_count},
            "levels": {"t1": self.levels[0], "t2": self.levels[1]},
            "budget": self.budget,
            "colour": self.cloud.colour.source,
            "classes": [
                {"id": c.id, "name": c.name, "color": list(c.color), "ignore": c.ignore}
                for c in self.cloud.taxonomy.classes
            ],
            "cameras": cams,
            "frustum_depth_m": depth,
            "spacing_hint_m": _spacing_hint(self),
        }


def _spacing_hint(plan: CloudPlan) -> float:
    """About the spacing of the drawn points (metres): the viewer's point size."""
    n = sum(c.points for cs in plan.chunks for c in cs)
    area = max(float(plan.extent[0] * plan.extent[1]), 1e-6)
    return math.sqrt(area / max(n / 2, 1))
