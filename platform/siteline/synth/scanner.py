"""An airborne LiDAR flown over a synthetic epoch: parallel flight lines, a line scanner sweeping
across track, first returns found by exact ray casting of the epoch's surfaces, range noise along
the ray. What a line cannot see gets no points, a wall is sampled by how squarely the lines face it,
and each epoch's lines differ from the plan as real flights do (turned, shifted, higher or lower):
two scans of one surface never sample it alike. A canopy returns from inside its crown at a random
depth (other leaves in every scan) and lets some pulses through to what lies below.

Site-local metres, degrees counter-clockwise from east for headings.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, replace

import numpy as np

from siteline.errors import SynthError
from siteline.synth import model as m
from siteline.synth.lidar import (
    EpochChunk,
    LidarSpec,
    Visibility,
    airborne_snow,
    change_margin,
    dress,
    gps_week_seconds,
    surface_bounds,
    surface_keys,
)  # fmt: skip
from siteline.synth.primitives import Primitive
from siteline.synth.raycast import distances

SCANS = ("flown", "sampled")
# pulses are cast in blocks of this many scan lines x pulses of a line (a few metres of ground each)
BLOCK_ROWS, BLOCK_ANGLES = 64, 64


@dataclass(frozen=True)
class Flight:
    """One epoch's flight: lines along ``heading_deg`` ``spacing_m`` apart, the pattern shifted
    ``offset_m`` across track, flown at ``altitude_m`` above the site origin at ``speed_m_s``; the
    scanner sweeps across track to ``half_angle_deg`` either side of nadir, in even angle steps (so
    the ground is sampled densest under the line), with ``noise_m`` range noise (1 sigma)."""

    heading_deg: float
    altitude_m: float
    spacing_m: float
    offset_m: float = 0.0
    half_angle_deg: float = 35.0
    speed_m_s: float = 8.0
    noise_m: float = 0.02

    def __post_init__(self) -> None:
        if not (self.altitude_m > 0 and self.spacing_m > 0 and 0 < self.half_angle_deg < 80):
            raise SynthError(
                f"flight {self}: altitude and spacing must be positive, the half angle 0-80 degrees."
            )

    def steps(self, density_pts_m2: float) -> tuple[float, float]:
        """The scan's angle step (radians) and the step between scan lines along track (metres) that
        give ``density_pts_m2`` on flat ground on average over the lines' overlap: each line lays
        2 theta / (H a^2) pulses a metre of track, over a swath ``spacing_m`` apart from the next."""
        theta = math.radians(self.half_angle_deg)
        step = math.sqrt(2.0 * theta / (self.spacing_m * self.altitude_m * density_pts_m2))
        return step, self.altitude_m * step


# the plan each layout flies (its epochs vary it by VARIATION x flight_variation)
FLIGHTS = {
    "site": Flight(heading_deg=0.0, altitude_m=80.0, spacing_m=50.0),
    "boxes": Flight(heading_deg=0.0, altitude_m=70.0, spacing_m=45.0),
    "slope": Flight(heading_deg=20.0, altitude_m=70.0, spacing_m=30.0, noise_m=0.025),
}
# how far an epoch's lines stray from the plan at flight_variation 1, at most: turned (degrees),
# shifted across track (metres), higher or lower (metres); each drawn per epoch from the seed
VARIATION = (2.0, 2.5, 3.0)


def epoch_flight(layout: str, seed: int, e: int, variation: float = 1.0) -> Flight:
    """The flight of epoch ``e``: the layout's plan turned, shifted and raised or lowered by up to
    ``variation`` x VARIATION (0: every epoch flies the plan exactly)."""
    if layout not in FLIGHTS:
        raise SynthError(f"layout {layout!r}: no flight planned; use one of {', '.join(FLIGHTS)}.")
    if not (math.isfinite(variation) and 0 <= variation <= 10):
        raise SynthError(f"flight variation {variation!r} must be between 0 and 10.")
    plan = FLIGHTS[layout]
    turn, shift, climb = (
        np.random.default_rng([seed, e, 4242]).uniform(-1.0, 1.0, 3) * np.array(VARIATION) * variation
    )
    return replace(
        plan,
        heading_deg=plan.heading_deg + float(turn),
        offset_m=plan.offset_m + float(shift),
        altitude_m=plan.altitude_m + float(climb),
    )


@dataclass(frozen=True)
class _Line:
    """One flight line: its across-track position (metres), along-track start and its scan lines."""

    index: int
    across_m: float
    start_m: float
    rows: int


def _lines(
    flight: Flight, rect: tuple[float, float, float, float], step_m: float
) -> tuple[np.ndarray, np.ndarray, list[_Line]]:
    """The along-track and across-track unit vectors and the lines that cover ``rect``."""
    h = math.radians(flight.heading_deg)
    u, v = np.array([math.cos(h), math.sin(h), 0.0]), np.array([-math.sin(h), math.cos(h), 0.0])
    x0, x1, y0, y1 = rect
    corners = np.array([[x, y, 0.0] for x in (x0, x1) for y in (y0, y1)])
    a, c = corners @ u, corners @ v
    first = math.floor((c.min() - flight.offset_m) / flight.spacing_m)
    last = math.ceil((c.max() - flight.offset_m) / flight.spacing_m)
    rows = int(math.ceil((a.max() - a.min()) / step_m)) + 1
    lines = [
        _Line(k - first, flight.offset_m + k * flight.spacing_m, float(a.min()), rows)
        for k in range(first, last + 1)
    ]
    return u, v, lines


def _canopy_depths(o: np.ndarray, d: np.ndarray, params: tuple, rng: np.random.Generator) -> np.ndarray:
    """Where each ray returns from a canopy (cx, cy, cz, r, depth_m): an exponential depth of mean
    depth_m past where it enters the crown's sphere, inf where that lies beyond where it leaves
    (the pulse went through) or where it misses."""
    cx, cy, cz, r, depth_m = params
    oc = o - np.array([cx, cy, cz])
    b = np.einsum("ij,ij->i", d, oc)
    c = np.einsum("ij,ij->i", oc, oc) - r * r
    disc = b * b - c
    out = np.full(len(d), np.inf)
    ok = disc > 0
    sq = np.sqrt(disc[ok])
    t_in, t_out = -b[ok] - sq, -b[ok] + sq
    t = t_in + rng.exponential(depth_m, len(t_in))
    out[ok] = np.where((t_in > 0) & (t < t_out), t, np.inf)
    return out


class _Caster:
    """First hits of rays on an epoch's surfaces. Each surface is cast only with the rays that can
    meet its bounding box (their plan position at its top and bottom brackets it), so the cost
    grows with the rays and the surfaces they pass near, not rays x surfaces."""

    def __init__(self, prims: list[Primitive]) -> None:
        self.prims = prims
        boxes = np.stack([surface_bounds(p) for p in prims]) if prims else np.zeros((0, 8, 3))
        self.lo, self.hi = boxes.min(axis=1), boxes.max(axis=1)

    def first_hits(
        self, o: np.ndarray, d: np.ndarray, rng: np.random.Generator, bounds: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(N,) distance along each ray to its first surface (inf where none) and that surface's index;
        the rays in blocks of neighbours (``bounds``: where each block starts, and the end), each cast
        with the surfaces near it."""
        best = np.full(len(d), np.inf)
        which = np.full(len(d), -1, np.int64)
        for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
            best[lo:hi], which[lo:hi] = self._block(o[lo:hi], d[lo:hi], rng)
        return best, which

    def _block(self, o: np.ndarray, d: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        best = np.full(len(d), np.inf)
        which = np.full(len(d), -1, np.int64)
        if not len(d):
            return best, which
        inv = 1.0 / d[:, 2]  # rays go down: d_z < 0
        # each ray's plan position at the scene's top and bottom, and the prims whose box their span meets
        zt, zb = float(self.hi[:, 2].max()), float(self.lo[:, 2].min())
        ends = np.stack([o[:, :2] + d[:, :2] * ((z - o[:, 2]) * inv)[:, None] for z in (zt, zb)])
        span_lo, span_hi = ends.min(axis=(0, 1)), ends.max(axis=(0, 1))
        near = np.flatnonzero(((self.lo[:, :2] <= span_hi) & (self.hi[:, :2] >= span_lo)).all(axis=1))
        for i in near:
            lo, hi = self.lo[i], self.hi[i]
            a = o[:, :2] + d[:, :2] * ((hi[2] - o[:, 2]) * inv)[:, None]
            b = o[:, :2] + d[:, :2] * ((lo[2] - o[:, 2]) * inv)[:, None]
            meet = np.flatnonzero(((np.minimum(a, b) <= hi[:2]) & (np.maximum(a, b) >= lo[:2])).all(axis=1))
            if not len(meet):
                continue
            prim = self.prims[i]
            if prim.kind == "canopy":
                t = _canopy_depths(o[meet], d[meet], prim.params, rng)
            else:
                t = distances(o[meet], d[meet], prim)
            nearer = t < best[meet]
            best[meet[nearer]] = t[nearer]
            which[meet[nearer]] = i
        return best, which


def _changed(prim: Primitive, others: set[tuple[str, str]] | None) -> bool:
    """Whether ``prim`` is absent from the surfaces ``others`` of another epoch (False: no such epoch)."""
    return others is not None and (prim.key, prim.signature) not in others


class _Truth:
    """What an epoch's returns are told about their surfaces: whether each changed since the epoch
    before and until the one after, and how far (siteline.synth.lidar.change_margin), its snow and
    projection-error dressing (siteline.synth.lidar.dress)."""

    def __init__(self, site: m.SiteModel, e: int, spec: LidarSpec, rng: np.random.Generator) -> None:
        self.e, self.ep, self.rng = e, site.epochs[e], rng
        self.prims = site.primitives(e)
        others = {k: site.primitives(k) if 0 <= k < len(site.epochs) else None for k in (e - 1, e + 1)}
        self.keys = {k: surface_keys(p) if p is not None else None for k, p in others.items()}
        self.by_key = {k: {q.key: q for q in p} if p else None for k, p in others.items()}
        self.caches: dict[int, dict] = {e - 1: {}, e + 1: {}}
        occ = Visibility(self.prims, spec) if self.ep.snow or self.ep.projection_error else None
        self.seen = None if occ is None else (occ, site.jib_ground_footprint(e))

    def chunks(self, xyz: np.ndarray, times: np.ndarray, which: np.ndarray) -> Iterator[EpochChunk]:
        """The returns ``xyz`` at GPS ``times`` on surfaces ``which`` as one EpochChunk per surface."""
        e = self.e
        for i in np.unique(which):
            sel = np.flatnonzero(which == i)
            prim = self.prims[int(i)]
            before, after = (_changed(prim, self.keys[k]) for k in (e - 1, e + 1))
            chunk = dress(xyz[sel], times[sel], prim, self.rng, self.ep, self.seen, (before, after))
            chunk.margin_previous_m = change_margin(
                chunk.xyz, prim, before, self.by_key[e - 1], self.caches[e - 1]
            )
            chunk.margin_next_m = change_margin(
                chunk.xyz, prim, after, self.by_key[e + 1], self.caches[e + 1]
            )
            yield chunk


def fly_epoch(site: m.SiteModel, e: int, spec: LidarSpec, flight: Flight) -> Iterator[EpochChunk]:
    """Stream the first returns of ``flight`` over epoch ``e`` in chunks of about ``spec.chunk_points``
    pulses, with the epoch's ground truth (as siteline.synth.lidar.sample_epoch gives it)."""
    ep = site.epochs[e]
    rng = np.random.default_rng([site.seed, e, 7919])
    truth = _Truth(site, e, spec, rng)
    caster = _Caster(truth.prims)
    t0 = gps_week_seconds(ep.time.timestamp())
    step_rad, step_m = flight.steps(spec.density_pts_m2)
    theta = math.radians(flight.half_angle_deg)
    angles = np.arange(-theta + step_rad / 2, theta, step_rad)
    u, v, lines = _lines(flight, site.terrain_m, step_m)
    line_s = max(ln.rows for ln in lines) * step_m / flight.speed_m_s + 20.0
    per_chunk = max(BLOCK_ROWS, spec.chunk_points // len(angles) // BLOCK_ROWS * BLOCK_ROWS)
    for line in lines:
        for r0 in range(0, line.rows, per_chunk):
            rows = min(per_chunk, line.rows - r0)
            # jittered pulses: a scan line every step along track, a pulse every angle step across it
            along = (r0 + np.arange(rows)[:, None] + rng.uniform(-0.5, 0.5, (rows, len(angles)))) * step_m
            alpha = angles[None, :] + rng.uniform(-0.5, 0.5, (rows, len(angles))) * step_rad
            # cast in blocks of BLOCK_ROWS scan lines x BLOCK_ANGLES pulses (a few metres of ground),
            # each with the surfaces near it; the returns are kept in the order the pulses left
            grid = np.arange(rows)[:, None] // BLOCK_ROWS * (len(angles) // BLOCK_ANGLES + 1)
            block = (grid + np.arange(len(angles))[None, :] // BLOCK_ANGLES).ravel()
            order = np.argsort(block, kind="stable")
            bounds = np.r_[np.flatnonzero(np.diff(block[order])) + 1, len(block)]
            along, alpha = along.ravel()[order], alpha.ravel()[order]
            o = (
                (line.start_m + along)[:, None] * u
                + line.across_m * v
                + np.array([0.0, 0.0, flight.altitude_m])
            )
            d = np.sin(alpha)[:, None] * v + np.cos(alpha)[:, None] * np.array([0.0, 0.0, -1.0])
            t, which = caster.first_hits(o, d, rng, np.r_[0, bounds])
            back = np.argsort(order)
            o, d, t, which, along = o[back], d[back], t[back], which[back], along[back]
            hit = np.flatnonzero(np.isfinite(t))
            rng_noise = rng.normal(0.0, flight.noise_m, len(hit))
            xyz = o[hit] + (t[hit] + rng_noise)[:, None] * d[hit]
            # the lines are flown back and forth, one after the other
            run = along[hit] if line.index % 2 == 0 else line.rows * step_m - along[hit]
            times = t0 + line.index * line_s + run / flight.speed_m_s
            yield from truth.chunks(xyz, times, which[hit])
    if ep.snow:
        yield airborne_snow(site, e, spec, t0, np.random.default_rng([site.seed, e, 99_991]))
