"""Exporting (part of) a tiled scene to LAS/LAZ in the site CRS."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import laspy
import numpy as np

from siteline.lasio import labels_vlr, las_header
from siteline.site import SiteSpec
from siteline.tiles.reader import SceneTiles, in_bounds

ATTRS = ("rgb", "class", "intensity", "gps_time", "return_number")


def export_las(
    tiles: SceneTiles,
    site: SiteSpec,
    out: Path,
    bounds: Sequence[float] | None = None,
    level: int | None = None,
    labels: dict | None = None,
) -> int:
    """Write the scene's points (in ``bounds``, up to ``level``) to ``out`` (.las or .laz by suffix):
    LAS 1.4 point format 7, classification = site class ids (of the label set attached to ``tiles``),
    GPS time and return number as stored (they identify each point when corrected labels come back),
    scale = the tile quantum, offset near the data, the site CRS (WKT). ``labels``: what the classes
    mean (site, scene, label-set version, taxonomy), written as a siteline VLR. Tiles are read and
    written one at a time; returns the point count."""
    out = Path(out)
    lo = np.min([n.bounds_min for n in tiles.nodes], axis=0) + np.asarray(site.origin)
    header = las_header(site.crs, lo, scale=tiles.spec.quantum_m, point_format=7, version="1.4")
    if labels is not None:
        header.vlrs.append(labels_vlr(labels))
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.tmp{out.suffix}")
    n = 0
    origin = np.asarray(site.origin, dtype=np.float64)
    try:
        with laspy.open(tmp, mode="w", header=header) as writer:
            for tile in sorted(tiles.by_tile):
                data = tiles.read({tile: tiles.prefix(tile, level)}, ATTRS)
                xyz = data["xyz_m"]  # float64 site-local: export never goes through float32
                if bounds is not None:
                    keep = in_bounds(xyz, bounds)
                    data = {k: v[keep] for k, v in data.items()}
                    xyz = data["xyz_m"]
                if not len(xyz):
                    continue
                rec = laspy.ScaleAwarePointRecord.zeros(len(xyz), header=header)
                geo = xyz + origin
                rec.x, rec.y, rec.z = geo[:, 0], geo[:, 1], geo[:, 2]
                rgb16 = data["rgb"].astype(np.uint16) * 257
                rec.red, rec.green, rec.blue = rgb16[:, 0], rgb16[:, 1], rgb16[:, 2]
                rec.classification = data["class"]  # site class ids (point format 7 holds 0-255)
                rec.intensity = data["intensity"]
                rec.gps_time = data["gps_time"]
                rec.return_number = data["return_number"]
                writer.write_points(rec)
                n += len(xyz)
        tmp.replace(out)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return n
