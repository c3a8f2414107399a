"""Exporting (part of) a tiled scene to LAS/LAZ in the site CRS."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from siteline.pointpass import LasWriter, labels_vlr, las_header
from siteline.records.labelsets import ExportedLabels
from siteline.site.spec import SiteSpec
from siteline.stores import atomic_file
from siteline.tiles.reader import SceneTiles, in_bounds

ATTRS = ("rgb", "class", "intensity", "gps_time", "return_number")


def export_las(
    tiles: SceneTiles,
    site: SiteSpec,
    out: Path,
    bounds: Sequence[float] | None = None,
    level: int | None = None,
    labels: ExportedLabels | None = None,
) -> int:
    """Write the scene's points (in ``bounds``, up to ``level``) to ``out`` (.las or .laz by suffix):
    LAS 1.4 point format 7, classification = site class ids (of the label set attached to ``tiles``),
    GPS time and return number as stored (they identify each point when corrected labels come back),
    scale = the tile quantum, offset near the data, the site CRS (WKT). ``labels``: what the classes
    mean (site, scene, label-set version, taxonomy), written as a siteline VLR. Tiles are read and
    written one at a time; returns the point count."""
    lo = tiles.nodes.lo.min(axis=0) + np.asarray(site.origin)
    vlrs = [labels_vlr(labels.to_dict())] if labels is not None else []
    header = las_header(site.crs, lo, scale=tiles.spec.quantum_m, point_format=7, version="1.4", vlrs=vlrs)
    n = 0
    origin = np.asarray(site.origin, dtype=np.float64)
    with atomic_file(out) as tmp, LasWriter(tmp, header) as writer:
        for tile in sorted(tiles.by_tile):
            data = tiles.read_tile(tile, ATTRS, level)
            if bounds is not None:
                data = data.select(in_bounds(data.xyz_m, bounds))
            if not len(data):
                continue
            a = data.attributes  # classes are site class ids (point format 7 holds 0-255)
            writer.write(
                data.xyz_m + origin, rgb=a["rgb"], classification=a["class"], intensity=a["intensity"],
                gps_time=a["gps_time"], return_number=a["return_number"],
            )  # fmt: skip
            n += len(data)
    return n
