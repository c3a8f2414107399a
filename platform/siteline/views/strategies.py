"""The three view strategies of the paper, each a pure function of a camera (DESIGN.md §5)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from siteline.cameras import Camera
from siteline.fence import nearest_segment
from siteline.views.ground import GroundPlane


def vertical(camera: Camera, plane: GroundPlane, fraction: float) -> Camera:
    """Move the camera along the ground-plane normal to ``fraction`` of its height; orientation kept."""
    C = camera.center
    h = float(plane.height(C))
    n = np.asarray(plane.normal)
    return camera.with_center(C - (1.0 - fraction) * h * n)


def mirror_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """3x3 reflection across the vertical plane through the fence segment a-b ((2,) metres)."""
    d = np.asarray(b, dtype=np.float64) - np.asarray(a, dtype=np.float64)
    m = np.array([-d[1], d[0], 0.0]) / np.hypot(d[0], d[1])
    return np.eye(3) - 2.0 * np.outer(m, m)


def mirror(
    camera: Camera, fence_m: Sequence[Sequence[float]]
) -> tuple[Camera, tuple[tuple[float, float], tuple[float, float]]]:
    """Reflect the camera's centre and viewing direction across the nearest fence segment.

    The optical axis and the image-down axis are reflected and the right axis recomputed, so the
    result is a proper camera (not a mirror image) looking back across the fence. Mirroring twice
    across the same segment gives the original camera. Returns the camera and the segment used.
    """
    C = camera.center
    a, b = nearest_segment(C[:2], fence_m)
    M = mirror_matrix(a, b)
    anchor = np.array([a[0], a[1], 0.0])
    C2 = M @ (C - anchor) + anchor
    axes = camera.R  # rows: camera x, y, z in the world
    z2 = M @ axes[2]
    y2 = M @ axes[1]
    x2 = np.cross(y2, z2)
    R2 = np.stack([x2, y2, z2])
    return camera.with_pose(R2, -R2 @ C2), ((float(a[0]), float(a[1])), (float(b[0]), float(b[1])))


def forward(camera: Camera, distance_m: float) -> Camera:
    """Translate the camera ``distance_m`` along its optical axis."""
    return camera.with_center(camera.center + distance_m * camera.forward)
