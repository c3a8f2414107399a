"""Exporting (part of) a tiled scene to LAS/LAZ in the site CRS."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import laspy
import numpy as np

from siteline.pointpass.lasio import labels_vlr, las_header
from siteline.site.spec import SiteSpec
from siteline.stores import atomic_file
from siteline.tiles.reader import Points, SceneTiles, in_bounds

ATTRS = ("rgb", "class", "intensity", "gps_time", "return_number")


def export_las(
    tiles: SceneTiles,
    site: SiteSpec,
    out: Path,
    bounds: Sequence[float] | None = None,
    level: int | None = None,
    labels: dict[str, Any] | None = None,
) -> int:
    """Write the scene's points (in ``bounds``, up to ``level``) to ``out`` (.las or .laz by suffix):
    LAS 1.4 point format 7, classification = site class ids (of the label set attached to ``tiles``),
    GPS time and return number as stored (they identify each point when corrected labels come back),
    scale = the tile quantum, offset near the data, the site CRS (WKT). ``labels``: what the classes
    mean (site, scene, label-set version, taxonomy), written as a siteline VLR. Tiles are read and
    written one at a time; returns the point count."""
    lo = tiles.nodes.lo.min(axis=0) + np.asarray(site.origin)
    header = las_header(site.crs, lo, scale=tiles.spec.quantum_m, point_format=7, version="1.4")
    if labels is not None:
        header.vlrs.append(labels_vlr(labels))
    n = 0
    origin = np.asarray(site.origin, dtype=np.float64)
    with atomic_file(out) as tmp, laspy.open(tmp, mode="w", header=header) as writer:
        for tile in sorted(tiles.by_tile):
            data = tiles.read_tile(tile, ATTRS, level)
            if bounds is not None:
                data = data.select(in_bounds(data.xyz_m, bounds))
            if not len(data):
                continue
            writer.write_points(_record(data, header, origin))
            n += len(data)
    return n


def _record(data: Points, header: laspy.LasHeader, origin: np.ndarray) -> laspy.ScaleAwarePointRecord:
    """A LAS point record of ``data`` in the site CRS (float64 site-local + origin: never float32)."""
    rec = laspy.ScaleAwarePointRecord.zeros(len(data), header=header)
    geo = data.xyz_m + origin
    rec.x, rec.y, rec.z = geo[:, 0], geo[:, 1], geo[:, 2]
    a = data.attributes
    rgb16 = a["rgb"].astype(np.uint16) * 257
    rec.red, rec.green, rec.blue = rgb16[:, 0], rgb16[:, 1], rgb16[:, 2]
    rec.classification = a["class"]  # site class ids (point format 7 holds 0-255)
    rec.intensity = a["intensity"]
    rec.gps_time = a["gps_time"]
    rec.return_number = a["return_number"]
    return rec
