"""Exact ray casting of the synthetic site's analytic surfaces (siteline.synth.primitives).

The truth a release's masks are scored against must not come from the renderer that drew them: this
module intersects each pixel's ray with every primitive of an epoch in closed form (planes, quadrics,
the terrain's planar pieces), in float64 site-local metres, and returns which surface each pixel
sees first. It shares nothing with siteline.render but the camera convention (DESIGN.md §3: pixel
centres at (i + 0.5, j + 0.5), x right, y down, z forward).

Each surface is the one its primitive samples: a box has no bottom face, a cylinder no bottom cap, a
cone only its lateral surface, terrain is its height field over its rectangle (less ``exclude``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from siteline.camera.pinhole import Camera
from siteline.errors import SynthError
from siteline.synth.primitives import Primitive, _box_faces, pit_ramp_m, terrain_height

MISS = -1
# hits nearer than this (metres along the ray) are not surfaces in front of the camera
NEAR_M = 1e-6
# a terrain piece's plane hit belongs to the height field when it lies this close to it (metres)
HEIGHT_TOL_M = 1e-6


@dataclass(frozen=True)
class Rays:
    """One ray per pixel of a camera: ``origin`` (3,) site-local metres, ``dirs`` (H W, 3) unit
    vectors in row-major pixel order, ``shape`` (H, W)."""

    origin: np.ndarray
    dirs: np.ndarray
    shape: tuple[int, int]


def camera_rays(camera: Camera) -> Rays:
    """The rays through every pixel centre of ``camera`` (use ``camera.scaled(s)`` for a render
    scale), float64."""
    H, W = camera.height, camera.width
    u, v = np.meshgrid(np.arange(W, dtype=np.float64) + 0.5, np.arange(H, dtype=np.float64) + 0.5)
    cam = np.stack([(u.ravel() - camera.cx) / camera.fx, (v.ravel() - camera.cy) / camera.fy, np.ones(H * W)])
    world = (camera.R.T @ cam).T
    world /= np.linalg.norm(world, axis=1, keepdims=True)
    return Rays(np.asarray(camera.center, dtype=np.float64), world, (H, W))


Vec = Sequence[float] | np.ndarray


def _quad(o: np.ndarray, d: np.ndarray, origin: Vec, u: Vec, v: Vec) -> np.ndarray:
    """Ray parameter of each ray's hit on the parallelogram origin + a u + b v (a, b in [0, 1]), inf
    where it misses."""
    p0, eu, ev = (np.asarray(x, dtype=np.float64) for x in (origin, u, v))
    n = np.array(
        [eu[1] * ev[2] - eu[2] * ev[1], eu[2] * ev[0] - eu[0] * ev[2], eu[0] * ev[1] - eu[1] * ev[0]]
    )
    # coordinates in the (u, v) basis through the inverse of its Gram matrix (u, v need not be orthogonal)
    guu, guv, gvv = eu @ eu, eu @ ev, ev @ ev
    det = guu * gvv - guv * guv
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t = (p0 @ n - o @ n) / (d @ n)
        hit = o + t[:, None] * d - p0
        hu, hv = hit @ eu, hit @ ev
        a = (gvv * hu - guv * hv) / det
        b = (guu * hv - guv * hu) / det
    ok = np.isfinite(t) & (t > NEAR_M) & (a >= 0) & (a <= 1) & (b >= 0) & (b <= 1)
    return np.where(ok, t, np.inf)


def _box(
    o: np.ndarray, d: np.ndarray, center: Sequence[float], size: Sequence[float], yaw: float
) -> np.ndarray:
    t = np.full(len(d), np.inf)
    for face in _box_faces(center, size, yaw):
        t = np.minimum(t, _quad(o, d, *face))
    return t


def _nearest_root(
    a: np.ndarray, b: np.ndarray, c: np.ndarray, keep: Callable[[np.ndarray], np.ndarray]
) -> np.ndarray:
    """The smaller root t > NEAR_M of a t^2 + b t + c = 0 for which ``keep(t)`` holds, inf where none."""
    disc = b * b - 4 * a * c
    out = np.full(len(a), np.inf)
    ok = (disc >= 0) & (np.abs(a) > 1e-300)
    sq = np.sqrt(np.where(ok, disc, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        roots = ((-b - sq) / (2 * a), (-b + sq) / (2 * a))
    for r in roots:  # the pair is not ordered when a < 0; take the valid minimum
        good = ok & np.isfinite(r) & (r > NEAR_M) & keep(r)
        out = np.where(good & (r < out), r, out)
    return out


def _cylinder(
    o: np.ndarray, d: np.ndarray, cx: float, cy: float, z0: float, r: float, h: float
) -> np.ndarray:
    ox, oy = o[:, 0] - cx, o[:, 1] - cy
    a = d[:, 0] ** 2 + d[:, 1] ** 2
    b = 2 * (ox * d[:, 0] + oy * d[:, 1])
    c = ox * ox + oy * oy - r * r

    def within(t: np.ndarray) -> np.ndarray:
        z = o[:, 2] + t * d[:, 2]
        return (z >= z0) & (z <= z0 + h)

    side = _nearest_root(a, b, c, within)
    with np.errstate(divide="ignore", invalid="ignore"):
        tt = (z0 + h - o[:, 2]) / d[:, 2]
        x, y = o[:, 0] + tt * d[:, 0] - cx, o[:, 1] + tt * d[:, 1] - cy
    top = np.where(np.isfinite(tt) & (tt > NEAR_M) & (x * x + y * y <= r * r), tt, np.inf)
    return np.minimum(side, top)


def _cone(o: np.ndarray, d: np.ndarray, cx: float, cy: float, z0: float, r: float, h: float) -> np.ndarray:
    # (x - cx)^2 + (y - cy)^2 = k^2 (apex_z - z)^2, k = r / h, z in [z0, z0 + h]
    k2 = (r / h) ** 2
    ox, oy, oz = o[:, 0] - cx, o[:, 1] - cy, o[:, 2] - (z0 + h)
    a = d[:, 0] ** 2 + d[:, 1] ** 2 - k2 * d[:, 2] ** 2
    b = 2 * (ox * d[:, 0] + oy * d[:, 1] - k2 * oz * d[:, 2])
    c = ox * ox + oy * oy - k2 * oz * oz

    def within(t: np.ndarray) -> np.ndarray:
        z = o[:, 2] + t * d[:, 2]
        return (z >= z0) & (z <= z0 + h)

    return _nearest_root(a, b, c, within)


def _sphere(o: np.ndarray, d: np.ndarray, cx: float, cy: float, cz: float, r: float) -> np.ndarray:
    oc = o - np.array([cx, cy, cz])
    b = 2 * np.einsum("ij,ij->i", d, oc)
    c = np.einsum("ij,ij->i", oc, oc) - r * r
    return _nearest_root(np.ones(len(d)), b, c, lambda t: np.ones(len(t), bool))


def _terrain_pieces(
    slope: tuple[float, float], pit: tuple[float, ...] | None
) -> list[tuple[float, float, float]]:
    """The planes z = a x + b y + c the terrain's height field is made of: its slope, and with a pit
    the four ramps (siteline.synth.primitives.pit_ramp_m wide) and the floor."""
    sx, sy = slope
    pieces = [(sx, sy, 0.0)]
    if pit is not None and pit[4] > 0:
        px0, px1, py0, py1, depth = pit[:5]
        k = depth / pit_ramp_m(pit)  # the ramp drops depth over its width
        pieces += [
            (sx - k, sy, k * px0),  # west ramp: - depth (x - px0) / 2
            (sx + k, sy, -k * px1),  # east ramp
            (sx, sy - k, k * py0),  # south ramp
            (sx, sy + k, -k * py1),  # north ramp
            (sx, sy, -depth),  # floor
        ]
    return pieces


def _terrain(
    o: np.ndarray, d: np.ndarray, rect: tuple[float, float, float, float], slope: tuple[float, float],
    pit: tuple[float, ...] | None, exclude: tuple[float, float, float, float] | None,
) -> np.ndarray:  # fmt: skip
    """The first hit on the height field (siteline.synth.primitives.terrain_height) over ``rect``,
    less ``exclude``: each planar piece's hit kept where the height field passes through it."""
    x0, x1, y0, y1 = rect
    out = np.full(len(d), np.inf)
    for a, b, c in _terrain_pieces(slope, pit):
        denom = d[:, 2] - a * d[:, 0] - b * d[:, 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (a * o[:, 0] + b * o[:, 1] + c - o[:, 2]) / denom
            x, y = o[:, 0] + t * d[:, 0], o[:, 1] + t * d[:, 1]
            z = o[:, 2] + t * d[:, 2]
        ok = np.isfinite(t) & (t > NEAR_M) & (x >= x0) & (x < x1) & (y >= y0) & (y < y1)
        if exclude is not None:
            ex0, ex1, ey0, ey1 = exclude
            ok &= ~((x >= ex0) & (x < ex1) & (y >= ey0) & (y < ey1))
        idx = np.flatnonzero(ok)
        on = np.abs(z[idx] - terrain_height(x[idx], y[idx], slope, pit)) <= HEIGHT_TOL_M * max(
            1.0, float(np.abs(c))
        )
        idx = idx[on]
        out[idx] = np.minimum(out[idx], t[idx])
    return out


def _canopy(
    o: np.ndarray, d: np.ndarray, cx: float, cy: float, cz: float, r: float, depth_m: float
) -> np.ndarray:
    """A crown's outer surface: its sphere (the leaves inside it are the scanner's, not the truth's)."""
    return _sphere(o, d, cx, cy, cz, r)


_CAST: dict[str, Callable[..., np.ndarray]] = {
    "quad": _quad,
    "box": _box,
    "cylinder": _cylinder,
    "cone": _cone,
    "sphere": _sphere,
    "canopy": _canopy,
    "terrain": _terrain,
}


def distances(origins: np.ndarray, dirs: np.ndarray, prim: Primitive) -> np.ndarray:
    """(N,) float64 distance (metres) along each ray (``origins`` and unit ``dirs``, (N, 3) site-local)
    to ``prim``'s surface, inf where it misses (or meets it nearer than NEAR_M)."""
    cast = _CAST.get(prim.kind)
    if cast is None:
        raise SynthError(f"surface {prim.key!r}: no ray caster for kind {prim.kind!r}.")
    return cast(np.asarray(origins, np.float64), np.asarray(dirs, np.float64), *prim.params)


def ray_distances(rays: Rays, prim: Primitive) -> np.ndarray:
    """(H W,) float64 distance (metres) along each of a camera's rays to ``prim``'s surface, inf
    where it misses."""
    return distances(np.broadcast_to(rays.origin, rays.dirs.shape), rays.dirs, prim)


@dataclass(frozen=True)
class SurfaceHits:
    """What each pixel sees first: ``which`` (H, W) int64 index into ``primitives`` (MISS where no
    surface), ``distance`` (H, W) metres along the ray (inf where none), ``points`` (H, W, 3)
    site-local metres of the hit (NaN where none)."""

    primitives: tuple[Primitive, ...]
    which: np.ndarray
    distance: np.ndarray
    points: np.ndarray


def cast(camera: Camera, primitives: Sequence[Primitive]) -> SurfaceHits:
    """The first surface of ``primitives`` each pixel of ``camera`` sees (exact; ties between
    surfaces at one distance go to the earlier primitive)."""
    rays = camera_rays(camera)
    best = np.full(len(rays.dirs), np.inf)
    which = np.full(len(rays.dirs), MISS, dtype=np.int64)
    for i, prim in enumerate(primitives):
        t = ray_distances(rays, prim)
        nearer = t < best
        best[nearer], which[nearer] = t[nearer], i
    pts = rays.origin + np.where(np.isfinite(best), best, np.nan)[:, None] * rays.dirs
    H, W = rays.shape
    return SurfaceHits(tuple(primitives), which.reshape(H, W), best.reshape(H, W), pts.reshape(H, W, 3))
