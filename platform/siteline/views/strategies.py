"""The three view strategies of the paper, each a pure function of a camera (DESIGN.md §5)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import shapely

from siteline.camera.pinhole import Camera
from siteline.errors import ViewsError
from siteline.records.enums import MIRROR_RULES
from siteline.site.fence import inside_fence, nearest_segment
from siteline.views.ground import GroundModel


def vertical(camera: Camera, ground: GroundModel, fraction: float) -> Camera:
    """Move the camera along the ground's up direction (a plane's normal, or world up over a terrain)
    to ``fraction`` of its height above the ground below it; orientation kept."""
    C = camera.center
    h = float(ground.height(C))
    n = np.asarray(ground.up)
    return camera.with_center(C - (1.0 - fraction) * h * n)


def mirror_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """3x3 reflection across the vertical plane through the fence segment a-b ((2,) metres)."""
    d = np.asarray(b, dtype=np.float64) - np.asarray(a, dtype=np.float64)
    m = np.array([-d[1], d[0], 0.0]) / np.hypot(d[0], d[1])
    return np.eye(3) - 2.0 * np.outer(m, m)


def ground_target(camera: Camera, ground: GroundModel) -> np.ndarray | None:
    """Where the camera's optical axis meets the ground ((3,) site-local metres), or None when it
    looks level or up, or meets none."""
    return ground.axis_hit(camera.center, camera.forward)


def mirror(
    camera: Camera,
    fence_m: Sequence[Sequence[float]],
    ground: GroundModel | None = None,
    rule: str = "aim-site",
) -> tuple[Camera, tuple[tuple[float, float], tuple[float, float]]]:
    """Reflect the camera's centre across the nearest fence segment, and orient it by ``rule``:

    - ``aim-site`` (default): look at the ground point the real camera looked at when that lies
      inside the fence, else at the ground below the fence's centroid; image up stays world up. Its
      optical axis therefore meets the ground inside the site. (Reflecting the direction too sent the
      axis out of the site for half of the mirrored oblique views: 15 of 32 met the ground inside.)
    - ``reflect``: reflect the optical axis and the image-down axis as well (the earlier rule), a
      proper camera looking back across the fence; mirroring twice gives the original camera.

    Returns the camera and the segment used.
    """
    if rule not in MIRROR_RULES:
        raise ViewsError(f"mirror rule {rule!r}: use one of {MIRROR_RULES}.")
    C = camera.center
    a, b = nearest_segment(C[:2], fence_m)
    M = mirror_matrix(a, b)
    anchor = np.array([a[0], a[1], 0.0])
    C2 = M @ (C - anchor) + anchor
    if ground is not None:  # over a terrain, the mirrored camera keeps its height above the ground
        C2 = ground.keep_height(C, C2)
    segment = ((float(a[0]), float(a[1])), (float(b[0]), float(b[1])))
    if rule == "aim-site":
        if ground is None:
            raise ViewsError("the aim-site mirror rule needs the ground plane.")
        target = ground_target(camera, ground)
        if target is None or not inside_fence(target[None, :2], fence_m)[0]:
            centroid = np.asarray(shapely.Polygon(fence_m).centroid.coords[0], dtype=np.float64)
            target = ground.point_below(centroid)
        if np.linalg.norm(target - C2) > 1e-6:
            aimed = Camera.look_at(
                C2, target, camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy
            )
            return aimed, segment
    axes = camera.R  # rows: camera x, y, z in the world
    z2 = M @ axes[2]
    y2 = M @ axes[1]
    x2 = np.cross(y2, z2)
    R2 = np.stack([x2, y2, z2])
    return camera.with_pose(R2, -R2 @ C2), segment


def forward(camera: Camera, distance_m: float) -> Camera:
    """Translate the camera ``distance_m`` along its optical axis."""
    return camera.with_center(camera.center + distance_m * camera.forward)
