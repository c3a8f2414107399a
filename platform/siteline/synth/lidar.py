"""LiDAR-like sampling of a synthetic epoch: surfaces at a density, kept only where the flight can see
them, with range noise, intensity, GPS time and return numbers; streamed in chunks with ground truth.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from siteline.synth import model as m
from siteline.synth.primitives import SAMPLE, Primitive, _box_faces

GPS_EPOCH_UNIX_S = 315964800.0  # 1980-01-06T00:00:00Z
SECONDS_PER_WEEK = 604800.0


@dataclass(frozen=True)
class LidarSpec:
    """density_pts_m2: surface sampling density. noise_m: range noise (1 sigma, metres).
    altitude_m: flight height above the site origin. line_spacing_m, speed_m_s: the lawnmower pattern
    that sets GPS times. chunk_points: points generated per chunk (bounds memory)."""

    density_pts_m2: float = 10.0
    noise_m: float = 0.02
    altitude_m: float = 80.0
    line_spacing_m: float = 40.0
    speed_m_s: float = 8.0
    chunk_points: int = 500_000
    oblique_tilts_deg: tuple[float, ...] = (35.0, 60.0)


@dataclass
class EpochChunk:
    """Points of one epoch chunk, site-local float64, with LAS attributes and ground truth."""

    xyz: np.ndarray
    rgb: np.ndarray
    las_class: np.ndarray
    intensity: np.ndarray
    gps_time: np.ndarray
    return_number: np.ndarray
    number_of_returns: np.ndarray
    object_id: np.ndarray
    changed_since_previous: np.ndarray
    changed_until_next: np.ndarray
    margin_previous_m: np.ndarray
    margin_next_m: np.ndarray


INTENSITY = {
    m.GROUND: 60,
    m.BUILDING: 150,
    m.CRANE: 200,
    m.VEHICLE: 180,
    m.VEG_MED: 80,
    m.VEG_HIGH: 95,
    m.TEMPORARY: 120,
    m.WORKER: 170,
    m.MATERIAL: 110,
    m.SNOW: 230,
    m.NOISE: 20,
}


def directions(tilts_deg: tuple[float, ...]) -> list[np.ndarray]:
    """Viewing directions (unit, sensor -> scene): nadir, then four azimuths per oblique tilt."""
    out = [np.array([0.0, 0.0, -1.0])]
    for tilt in tilts_deg:
        t = math.radians(tilt)
        for az in (45.0, 135.0, 225.0, 315.0):
            a = math.radians(az)
            out.append(np.array([math.sin(t) * math.cos(a), math.sin(t) * math.sin(a), -math.cos(t)]))
    return out


def surface_bounds(prim: Primitive) -> np.ndarray:
    """(8, 3) corners of a box that holds ``prim``'s surface (site-local metres)."""
    if prim.kind == "terrain":
        rect, slope, pit, _ = prim.params
        x0, x1, y0, y1 = rect
        corners = np.array([[x, y] for x in (x0, x1) for y in (y0, y1)])
        z = corners @ np.asarray(slope, np.float64)
        lo, hi = z.min() - (pit[4] if pit is not None else 0.0), z.max()
        return np.array([[x, y, zz] for x in (x0, x1) for y in (y0, y1) for zz in (lo, hi)])
    if prim.kind == "quad":
        o, u, v = (np.asarray(a, np.float64) for a in prim.params)
        c = np.array([o, o + u, o + v, o + u + v])
    elif prim.kind == "box":
        c = np.concatenate(
            [np.array([f[0], f[0] + f[1], f[0] + f[2], f[0] + f[1] + f[2]]) for f in _box_faces(*prim.params)]
        )
    elif prim.kind in ("cylinder", "cone"):
        cx, cy, z0, r, h = prim.params
        c = np.array(
            [[cx + sx * r, cy + sy * r, z] for sx in (-1, 1) for sy in (-1, 1) for z in (z0, z0 + h)]
        )
    else:  # sphere or canopy
        cx, cy, cz, r = prim.params[:4]
        c = np.array(
            [[cx + sx * r, cy + sy * r, cz + sz * r] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
        )
    lo, hi = c.min(axis=0), c.max(axis=0)
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


# a surface met nearer than this along the way to the sensor is the point's own (metres)
SELF_M = 1e-4


class Visibility:
    """Which sampled points a flight sees: a point is seen along a scan direction when the ray from it
    towards the sensor meets no surface of the epoch (exact ray casting, siteline.synth.raycast),
    and seen when it is seen along at least one direction (nadir and four azimuths per oblique
    tilt). Each surface is tested only against the points in its shadow along the direction (its
    bounding box projected), so the cost grows with the points, not with points x surfaces."""

    def __init__(self, prims: list[Primitive], spec: LidarSpec) -> None:
        self.prims = prims
        self.dirs = directions(spec.oblique_tilts_deg)
        corners = np.stack([surface_bounds(p) for p in prims]) if prims else np.zeros((0, 8, 3))
        # per direction: its plane's axes and each surface's shadow rectangle and nearest depth on it
        self.frames = []
        for d in self.dirs:
            e1 = np.cross(d, [0.0, 1.0, 0.0]) if abs(d[1]) < 0.9 else np.cross(d, [1.0, 0.0, 0.0])
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(d, e1)
            ca, cb, cd = corners @ e1, corners @ e2, corners @ d
            rect = np.stack(
                [ca.min(axis=1), ca.max(axis=1), cb.min(axis=1), cb.max(axis=1), cd.min(axis=1)], axis=1
            )
            self.frames.append((d, e1, e2, rect))

    def visible(self, xyz: np.ndarray) -> np.ndarray:
        """(N,) bool: seen along at least one direction."""
        out = np.zeros(len(xyz), bool)
        for k in range(len(self.dirs)):
            left = np.flatnonzero(~out)
            if not len(left):
                break
            out[left[self._seen(xyz[left], k)]] = True
        return out

    def visible_from_above(self, xyz: np.ndarray) -> np.ndarray:
        return self._seen(xyz, 0)

    def _seen(self, xyz: np.ndarray, k: int) -> np.ndarray:
        from siteline.synth.raycast import distances

        d, e1, e2, rect = self.frames[k]
        blocked = np.zeros(len(xyz), bool)
        if not len(xyz):
            return ~blocked
        a, b, depth = xyz @ e1, xyz @ e2, xyz @ d
        # only the surfaces whose shadow rectangle meets these points' and that lie nearer the sensor
        near = (
            (rect[:, 1] >= a.min())
            & (rect[:, 0] <= a.max())
            & (rect[:, 3] >= b.min())
            & (rect[:, 2] <= b.max())
        )
        near &= rect[:, 4] < depth.max()
        for i in np.flatnonzero(near):
            a0, a1, b0, b1, d0 = rect[i]
            idx = np.flatnonzero((a >= a0) & (a <= a1) & (b >= b0) & (b <= b1) & (depth > d0) & ~blocked)
            if not len(idx):
                continue
            t = distances(xyz[idx], np.broadcast_to(-d, (len(idx), 3)), self.prims[i])
            blocked[idx[np.isfinite(t) & (t > SELF_M)]] = True
        return ~blocked


def flight_lines_y(spec: LidarSpec, rect: tuple[float, float, float, float] = m.TERRAIN_M) -> np.ndarray:
    x0, x1, y0, y1 = rect
    return np.arange(y0 + spec.line_spacing_m / 2, y1, spec.line_spacing_m)


def gps_week_seconds(t_unix: float) -> float:
    return (t_unix - GPS_EPOCH_UNIX_S) % SECONDS_PER_WEEK


def _times_and_sensors(
    xyz: np.ndarray, spec: LidarSpec, t0: float, rect: tuple[float, float, float, float]
) -> tuple[np.ndarray, np.ndarray]:
    """GPS time (week seconds) of the pass that saw each point, and the sensor position then."""
    x0, x1, _, _ = rect
    lines = flight_lines_y(spec, rect)
    k = np.abs(xyz[:, 1:2] - lines[None, :]).argmin(axis=1)
    line_s = (x1 - x0) / spec.speed_m_s + 20.0
    along = np.where(k % 2 == 0, xyz[:, 0] - x0, x1 - xyz[:, 0]) / spec.speed_m_s
    t = t0 + k * line_s + along
    sensors = np.c_[xyz[:, 0], lines[k], np.full(len(xyz), spec.altitude_m)]
    return t, sensors


def surface_keys(prims: list[Primitive]) -> set[tuple[str, str]]:
    return {(p.key, p.signature) for p in prims}


MARGIN_DENSITY_PTS_M2 = 60.0


def change_margin(
    xyz: np.ndarray, prim: Primitive, changed: bool, others: dict[str, Primitive] | None, cache: dict
) -> np.ndarray:
    """Distance (m) from each point of a changed surface to that surface's version in the other epoch
    (0 for unchanged surfaces, inf when it has no other version): how far the change really moved it."""
    if not changed:
        return np.zeros(len(xyz), np.float32)
    other = (others or {}).get(prim.key)
    if other is None:
        return np.full(len(xyz), np.inf, np.float32)
    tree = cache.get(prim.key)
    if tree is None:
        from scipy.spatial import cKDTree

        rng = np.random.default_rng(zlib.crc32(prim.key.encode()))
        n = max(10, int(MARGIN_DENSITY_PTS_M2 * other.area_m2()))
        tree = cKDTree(SAMPLE[other.kind](n, rng, *other.params))
        cache[prim.key] = tree
    return tree.query(xyz, k=1)[0].astype(np.float32)


def sample_epoch(site: m.SiteModel, e: int, spec: LidarSpec) -> Iterator[EpochChunk]:
    """Stream the LiDAR points of epoch ``e`` in chunks of at most ``spec.chunk_points``."""
    ep = site.epochs[e]
    prims = site.primitives(e)
    prev_prims = site.primitives(e - 1) if e > 0 else None
    next_prims = site.primitives(e + 1) if e + 1 < len(site.epochs) else None
    prev = surface_keys(prev_prims) if prev_prims is not None else None
    nxt = surface_keys(next_prims) if next_prims is not None else None
    prev_by_key = {p.key: p for p in prev_prims} if prev_prims else None
    next_by_key = {p.key: p for p in next_prims} if next_prims else None
    cache_prev: dict = {}
    cache_next: dict = {}
    occ = Visibility(prims, spec)
    t0 = gps_week_seconds(ep.time.timestamp())
    base_seed = site.seed * 100_003 + e * 1009
    jib_c, jib_d, jib_len = site.jib_ground_footprint(e)
    for pi, prim in enumerate(prims):
        rng = np.random.default_rng([base_seed, pi])
        n_total = int(rng.poisson(spec.density_pts_m2 * prim.area_m2()))
        changed_prev = prev is not None and (prim.key, prim.signature) not in prev
        changed_next = nxt is not None and (prim.key, prim.signature) not in nxt
        for start in range(0, n_total, spec.chunk_points):
            n = min(spec.chunk_points, n_total - start)
            xyz = SAMPLE[prim.kind](n, rng, *prim.params)
            xyz = xyz[occ.visible(xyz)]
            if not len(xyz):
                continue
            chunk = _finish(
                xyz, prim, rng, spec, (t0, site.terrain_m), ep, (occ, (jib_c, jib_d, jib_len)),
                (changed_prev, changed_next),
            )  # fmt: skip
            chunk.margin_previous_m = change_margin(chunk.xyz, prim, changed_prev, prev_by_key, cache_prev)
            chunk.margin_next_m = change_margin(chunk.xyz, prim, changed_next, next_by_key, cache_next)
            yield chunk
    if ep.snow:
        rng = np.random.default_rng([base_seed, 99_991])
        yield airborne_snow(site, e, spec, t0, rng)


def airborne_snow(
    site: m.SiteModel, e: int, spec: LidarSpec, t0: float, rng: np.random.Generator
) -> EpochChunk:
    """Snowflakes in the air over the terrain (3-35 m), 0.02 a square metre of it."""
    x0, x1, y0, y1 = site.terrain_m
    n = int(rng.poisson(0.02 * (x1 - x0) * (y1 - y0)))
    xyz = np.c_[rng.uniform(x0, x1, n), rng.uniform(y0, y1, n), rng.uniform(3, 35, n)]
    flake = Primitive("snow:airborne", f"e{e}", 900, m.SNOW, "sphere", (0, 0, 0, 1), (245, 245, 250))
    return _finish(xyz, flake, rng, spec, (t0, site.terrain_m), site.epochs[e], None, (False, False))


def _finish(
    xyz: np.ndarray, prim: Primitive, rng: np.random.Generator, spec: LidarSpec,
    clock: tuple[float, tuple[float, float, float, float]], ep: m.EpochSpec,
    seen: tuple[Visibility, tuple[np.ndarray, np.ndarray, float]] | None, changed: tuple[bool, bool],
) -> EpochChunk:  # fmt: skip
    """A primitive's sampled points as a LiDAR chunk: times (``clock``: the epoch's first GPS time and
    the terrain the lawnmower lines cross), range noise, then :func:`dress`."""
    t, sensors = _times_and_sensors(xyz, spec, *clock)
    ray = xyz - sensors
    ray /= np.linalg.norm(ray, axis=1, keepdims=True) + 1e-12
    xyz = xyz + ray * rng.normal(0.0, spec.noise_m, (len(xyz), 1))
    return dress(xyz, t, prim, rng, ep, seen, changed)


def dress(
    xyz: np.ndarray, t: np.ndarray, prim: Primitive, rng: np.random.Generator, ep: m.EpochSpec,
    seen: tuple[Visibility, tuple[np.ndarray, np.ndarray, float]] | None, changed: tuple[bool, bool],
) -> EpochChunk:  # fmt: skip
    """Returns on ``prim`` at GPS times ``t`` as a LiDAR chunk: colour, returns, intensity; ``seen``:
    the epoch's visibility (siteline.synth.lidar.Visibility) and the crane jib's ground footprint
    (snow on what is seen from above, the jib's projection error smeared on the ground; None:
    neither); ``changed``: whether the surface changed since the previous epoch and until the next."""
    n = len(xyz)
    occ, jib = seen if seen is not None else (None, None)
    changed_prev, changed_next = changed
    rgb = np.clip(np.asarray(prim.colour, float) + rng.normal(0, 8, (n, 3)), 0, 255)
    if occ is not None and ep.snow and prim.upward:
        top = occ.visible_from_above(xyz)
        rgb[top] = np.clip(rng.normal(242, 4, (int(top.sum()), 3)), 0, 255)
        xyz[top, 2] += 0.05
    if occ is not None and ep.projection_error and prim.las_class == m.GROUND and jib is not None:
        c, d, length = jib
        rel = xyz[:, :2] - c
        along = rel @ d
        across = np.abs(rel @ np.array([-d[1], d[0]]))
        smear = (np.abs(along) < length / 2) & (across < 1.5)
        rgb[smear] = (230, 50, 35)
    ret = np.ones(n, np.uint8)
    nret = np.ones(n, np.uint8)
    if prim.las_class in (m.VEG_LOW, m.VEG_MED, m.VEG_HIGH):
        nret[:] = 3
        ret = rng.integers(1, 4, n).astype(np.uint8)
    intensity = np.clip(INTENSITY.get(prim.las_class, 100) + rng.normal(0, 12, n), 0, 255).astype(np.uint16)
    return EpochChunk(
        xyz=xyz,
        rgb=rgb.astype(np.uint8),
        las_class=np.full(n, prim.las_class, np.uint8),
        intensity=intensity,
        gps_time=t,
        return_number=ret,
        number_of_returns=nret,
        object_id=np.full(n, prim.object_id, np.int32),
        changed_since_previous=np.full(n, changed_prev),
        changed_until_next=np.full(n, changed_next),
        margin_previous_m=np.zeros(n, np.float32),
        margin_next_m=np.zeros(n, np.float32),
    )
