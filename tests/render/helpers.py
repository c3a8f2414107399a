"""Small synthetic scenes for renderer and view tests (seeded, site-local metres)."""

from __future__ import annotations

import numpy as np

from siteline.camera.pinhole import Camera


def plane_points(z: float, half: float, step: float) -> np.ndarray:
    """A horizontal square grid at height z, (N, 3) float64."""
    g = np.arange(-half, half + step / 2, step)
    xx, yy = np.meshgrid(g, g)
    return np.stack([xx.ravel(), yy.ravel(), np.full(xx.size, z)], axis=1)


def box_scene(seed: int = 0, n: int = 20_000) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ground plane plus two boxes; coordinates are multiples of 2^-10 m (exact in float32 and in
    float64 after adding a georeferenced origin). Returns xyz (N, 3) float64, rgb (N, 3) uint8, class (N,)."""
    rng = np.random.default_rng(seed)
    q = 1.0 / 1024
    ground = np.c_[rng.uniform(-40, 40, (n, 2)), rng.uniform(-0.05, 0.05, n)]
    b1 = np.c_[rng.uniform(-10, -2, (n // 4, 2)), rng.uniform(0, 8, n // 4)]
    b2 = np.c_[rng.uniform(5, 15, (n // 4, 2)), rng.uniform(0, 3, n // 4)]
    xyz = np.round(np.concatenate([ground, b1, b2]) / q) * q
    cls = np.concatenate([np.full(n, 1), np.full(n // 4, 2), np.full(n // 4, 4)]).astype(np.uint8)
    rgb = rng.integers(0, 256, (len(xyz), 3), dtype=np.uint8)
    return xyz, rgb, cls


def oblique_camera(width: int = 160, height: int = 120) -> Camera:
    return Camera.look_at(
        (-30.0, -35.0, 25.0),
        (0.0, 0.0, 0.0),
        width,
        height,
        fx=0.75 * width,
        fy=0.75 * width + 1.0,
        cx=0.508 * width,
        cy=0.489 * height,
    )
