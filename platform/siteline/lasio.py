"""Reading LAS/LAZ files into site-local arrays, streamed in chunks (laspy + lazrs).

Coordinates go from the file's integer counts to float64 CRS metres (laspy's scale and offset) and
then to site-local by float64 subtraction of the site origin, chunk by chunk; only then to float32.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import laspy
import numpy as np

from siteline.errors import PointCloudError

DEFAULT_CHUNK_POINTS = 1_000_000
# Beyond this, float32 site-local coordinates lose millimetres: the origin is wrong or missing.
MAX_SITE_LOCAL_M = 20_000.0


@dataclass
class PointChunk:
    """One chunk of points. xyz_crs: (N, 3) float64 georeferenced (CRS units). rgb: (N, 3) uint8 or
    None. classification: (N,) uint8 source codes. intensity: (N,) uint16. gps_time: (N,) float64 or
    None. return_number: (N,) uint8."""

    xyz_crs: np.ndarray
    rgb: np.ndarray | None
    classification: np.ndarray
    intensity: np.ndarray
    gps_time: np.ndarray | None
    return_number: np.ndarray


def colour_to_u8(rgb16: np.ndarray, eight_bit: bool) -> np.ndarray:
    """LAS colour (N, 3) uint16 -> uint8: 8-bit values stored in 16-bit fields are kept, true 16-bit
    values are shifted down by 8 bits."""
    if eight_bit:
        return rgb16.astype(np.uint8)
    return (rgb16 >> 8).astype(np.uint8)


def open_las(path: Path) -> laspy.LasReader:
    """Open a LAS/LAZ file for streaming; :class:`PointCloudError` naming the file when it is unreadable."""
    path = Path(path)
    if not path.is_file():
        raise PointCloudError(f"point cloud {path} does not exist.")
    try:
        return laspy.open(path)
    except (laspy.LaspyException, OSError, ValueError) as exc:
        raise PointCloudError(f"point cloud {path} is not a readable LAS/LAZ file: {exc}") from exc


def iter_chunks(
    path: Path, chunk_points: int = DEFAULT_CHUNK_POINTS, eight_bit: bool | None = None
) -> Iterator[PointChunk]:
    """Stream a LAS/LAZ file as :class:`PointChunk` s. ``eight_bit`` (colour stored as 0-255 in 16-bit
    fields) is detected from the first chunk when None."""
    with open_las(path) as reader:
        has_rgb = "red" in reader.header.point_format.dimension_names
        has_time = "gps_time" in reader.header.point_format.dimension_names
        try:
            for pts in reader.chunk_iterator(chunk_points):
                xyz = np.stack(
                    [
                        np.asarray(pts.x, dtype=np.float64),
                        np.asarray(pts.y, dtype=np.float64),
                        np.asarray(pts.z, dtype=np.float64),
                    ],
                    axis=1,
                )
                rgb = None
                if has_rgb:
                    rgb16 = np.stack(
                        [np.asarray(pts.red), np.asarray(pts.green), np.asarray(pts.blue)], axis=1
                    )
                    if eight_bit is None:
                        eight_bit = bool(rgb16.max(initial=0) <= 255)
                    rgb = colour_to_u8(rgb16, eight_bit)
                yield PointChunk(
                    xyz_crs=xyz,
                    rgb=rgb,
                    classification=np.asarray(pts.classification, dtype=np.uint8),
                    intensity=np.asarray(pts.intensity, dtype=np.uint16),
                    gps_time=np.asarray(pts.gps_time, dtype=np.float64) if has_time else None,
                    return_number=np.asarray(pts.return_number, dtype=np.uint8),
                )
        except (laspy.LaspyException, OSError, ValueError, RuntimeError) as exc:
            raise PointCloudError(f"point cloud {path} is truncated or corrupt: {exc}") from exc


@dataclass
class SiteLocalCloud:
    """A whole (small) cloud in the site-local frame. xyz: (N, 3) float32 metres; rgb (N, 3) uint8 or
    None; classification (N,) uint8 source codes."""

    xyz: np.ndarray
    rgb: np.ndarray | None
    classification: np.ndarray


def read_site_local(
    path: Path, origin: Sequence[float], chunk_points: int = DEFAULT_CHUNK_POINTS
) -> SiteLocalCloud:
    """Read a LAS/LAZ file whole into site-local float32 (for renders and tools on small clouds).

    Raises :class:`PointCloudError` when a coordinate is not finite or lands further than
    ``MAX_SITE_LOCAL_M`` from the origin (float32 would silently lose precision).
    """
    xyzs, rgbs, classes = [], [], []
    o = np.asarray(origin, dtype=np.float64)
    for chunk in iter_chunks(path, chunk_points):
        local = chunk.xyz_crs - o
        if not np.isfinite(local).all():
            raise PointCloudError(f"point cloud {path} holds non-finite coordinates.")
        far = np.abs(local).max(initial=0.0)
        if far > MAX_SITE_LOCAL_M:
            raise PointCloudError(
                f"point cloud {path} has points {far:.0f} m from the origin {tuple(o)}; give the site origin "
                "(e.g. --origin X Y Z near the data): float32 would lose precision there."
            )
        xyzs.append(local.astype(np.float32))
        classes.append(chunk.classification)
        if chunk.rgb is not None:
            rgbs.append(chunk.rgb)
    xyz = np.concatenate(xyzs) if xyzs else np.zeros((0, 3), np.float32)
    cls = np.concatenate(classes) if classes else np.zeros(0, np.uint8)
    rgb = np.concatenate(rgbs) if rgbs else None
    return SiteLocalCloud(xyz=xyz, rgb=rgb, classification=cls)
