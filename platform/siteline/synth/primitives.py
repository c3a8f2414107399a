"""Surfaces of the synthetic site and their uniform sampling at a density (points per m2).

Every primitive samples ``Poisson(density x area)`` points uniformly over its surface with its own
generator, so the same seed gives the same points whatever else the site holds.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Primitive:
    """One sampled surface of one object.

    key: stable name of the surface (its identity across epochs). signature: its geometry; the same
    key and signature in two epochs means the same surface. object_id: the object it belongs to.
    las_class: ASPRS/siteline source code written to LAS. kind + params: the geometry (site-local
    metres; a ``canopy`` is a crown (cx, cy, cz, r, depth_m) whose returns lie inside its sphere at an
    exponential depth of mean depth_m, the sphere being its surface for the truth). colour: RGB uint8. upward: whether snow settles on it.
    """

    key: str
    signature: str
    object_id: int
    las_class: int
    kind: str
    params: tuple
    colour: tuple[int, int, int]
    upward: bool = False

    def area_m2(self) -> float:
        return AREA[self.kind](*self.params)

    def sample(self, density: float, rng: np.random.Generator) -> np.ndarray:
        """(N, 3) float64 site-local points on the surface."""
        n = int(rng.poisson(density * self.area_m2()))
        return SAMPLE[self.kind](n, rng, *self.params)


Vec = Sequence[float] | np.ndarray
Rng = np.random.Generator


def _quad_area(origin: Vec, u: Vec, v: Vec) -> float:
    return float(np.linalg.norm(np.cross(u, v)))


def _quad(n: int, rng: Rng, origin: Vec, u: Vec, v: Vec) -> np.ndarray:
    a = rng.random((n, 2))
    return np.asarray(origin) + a[:, :1] * np.asarray(u) + a[:, 1:] * np.asarray(v)


def _box_faces(
    center: Vec, size: Vec, yaw: float, top: bool = True
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    cx, cy, z0 = center
    sx, sy, sz = size
    c, s = math.cos(yaw), math.sin(yaw)
    ex, ey = np.array([c, s, 0.0]) * sx, np.array([-s, c, 0.0]) * sy
    ez = np.array([0.0, 0.0, sz])
    o = np.array([cx, cy, z0]) - ex / 2 - ey / 2
    faces = [(o, ex, ez), (o + ey, ex, ez), (o, ey, ez), (o + ex, ey, ez)]
    if top:
        faces.append((o + ez, ex, ey))
    return faces


def _box_area(center: Vec, size: Vec, yaw: float) -> float:
    return sum(_quad_area(*f) for f in _box_faces(center, size, yaw))


def _box(n: int, rng: Rng, center: Vec, size: Vec, yaw: float) -> np.ndarray:
    faces = _box_faces(center, size, yaw)
    areas = np.array([_quad_area(*f) for f in faces])
    which = rng.choice(len(faces), n, p=areas / areas.sum())
    out = np.empty((n, 3))
    for i, f in enumerate(faces):
        m = which == i
        out[m] = _quad(int(m.sum()), rng, *f)
    return out


def _cyl_area(cx: float, cy: float, z0: float, r: float, h: float) -> float:
    return 2 * math.pi * r * h + math.pi * r * r


def _cyl(n: int, rng: Rng, cx: float, cy: float, z0: float, r: float, h: float) -> np.ndarray:
    side = 2 * math.pi * r * h
    top = math.pi * r * r
    on_top = rng.random(n) < top / (side + top)
    th = rng.uniform(0, 2 * math.pi, n)
    rr = np.where(on_top, r * np.sqrt(rng.random(n)), r)
    z = np.where(on_top, z0 + h, z0 + rng.random(n) * h)
    return np.c_[cx + rr * np.cos(th), cy + rr * np.sin(th), z]


def _cone_area(cx: float, cy: float, z0: float, r: float, h: float) -> float:
    return math.pi * r * math.hypot(r, h)


def _cone(n: int, rng: Rng, cx: float, cy: float, z0: float, r: float, h: float) -> np.ndarray:
    rr = r * np.sqrt(rng.random(n))
    th = rng.uniform(0, 2 * math.pi, n)
    return np.c_[cx + rr * np.cos(th), cy + rr * np.sin(th), z0 + h * (1 - rr / r)]


def _sphere_area(cx: float, cy: float, cz: float, r: float) -> float:
    return 4 * math.pi * r * r


def _sphere(n: int, rng: Rng, cx: float, cy: float, cz: float, r: float) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True) + 1e-300
    return np.array([cx, cy, cz]) + r * v


def _canopy_area(cx: float, cy: float, cz: float, r: float, depth_m: float) -> float:
    return _sphere_area(cx, cy, cz, r)


def _canopy(n: int, rng: Rng, cx: float, cy: float, cz: float, r: float, depth_m: float) -> np.ndarray:
    """Leaves of a crown: points on its sphere pushed inwards by an exponential depth of mean
    ``depth_m`` (the returns of a canopy lie in a shell, not on a surface; each draw is other leaves)."""
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True) + 1e-300
    depth = np.minimum(rng.exponential(depth_m, n), r)
    return np.array([cx, cy, cz]) + (r - depth)[:, None] * v


def _terrain_area(rect: tuple[float, float, float, float], *rest: object) -> float:
    x0, x1, y0, y1 = rect
    return (x1 - x0) * (y1 - y0)


# the width (metres) over which a pit's sides ramp down to its floor, unless the pit gives its own
PIT_RAMP_M = 2.0


def pit_ramp_m(pit: tuple) -> float:
    """The ramp width (metres) of a pit (x0, x1, y0, y1, depth[, ramp_m])."""
    return float(pit[5]) if len(pit) > 5 else PIT_RAMP_M


def terrain_height(x: np.ndarray, y: np.ndarray, slope: tuple[float, float], pit: tuple | None) -> np.ndarray:
    """Ground height (metres) of the terrain: a plane minus the excavation pit, whose sides ramp
    over its ramp width (2 m unless given). pit: (x0, x1, y0, y1, depth[, ramp_m]) or None."""
    z = slope[0] * x + slope[1] * y
    if pit is not None:
        px0, px1, py0, py1, depth = pit[:5]
        if depth > 0:
            dx = np.minimum(x - px0, px1 - x)
            dy = np.minimum(y - py0, py1 - y)
            inside = np.clip(np.minimum(dx, dy) / pit_ramp_m(pit), 0.0, 1.0)
            z = z - depth * inside
    return z


def _terrain(
    n: int, rng: Rng, rect: tuple[float, float, float, float], slope: tuple[float, float],
    pit: tuple[float, ...] | None, exclude: tuple[float, float, float, float] | None,
) -> np.ndarray:  # fmt: skip
    """Terrain over the rectangle ``rect`` (x0, x1, y0, y1), optionally only inside (pit region) or
    outside (``exclude``) a box."""
    x0, x1, y0, y1 = rect
    x = rng.uniform(x0, x1, n)
    y = rng.uniform(y0, y1, n)
    keep = np.ones(n, bool)
    if exclude is not None:
        ex0, ex1, ey0, ey1 = exclude
        keep = ~((x >= ex0) & (x < ex1) & (y >= ey0) & (y < ey1))
    x, y = x[keep], y[keep]
    return np.c_[x, y, terrain_height(x, y, slope, pit)]


AREA: dict[str, Callable[..., float]] = {
    "quad": _quad_area,
    "box": _box_area,
    "cylinder": _cyl_area,
    "cone": _cone_area,
    "sphere": _sphere_area,
    "canopy": _canopy_area,
    "terrain": _terrain_area,
}
SAMPLE: dict[str, Callable[..., np.ndarray]] = {
    "quad": _quad,
    "box": _box,
    "cylinder": _cyl,
    "cone": _cone,
    "sphere": _sphere,
    "canopy": _canopy,
    "terrain": _terrain,
}
