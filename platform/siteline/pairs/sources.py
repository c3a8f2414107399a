"""Scene geometry for view generation, served from the tile store."""

from __future__ import annotations

import numpy as np

from siteline.cameras import Camera
from siteline.tiles.reader import SceneTiles
from siteline.views.sources import ArrayPointSource


class TilePointSource:
    """A :class:`siteline.views.PointSource` over a tiled scene for view generation, which renders
    hundreds of probes per real camera. Each probe reads only what it needs: the tiles its frustum
    meets, at the spacing its own render scale and ``point_size_px`` need (``lod_factor``:
    ``SceneTiles.points_for_view``; the probes must render with the same point size), so a probe's
    cost grows with its pixels, not with the scene's density; the tile reader's cache keeps the tiles a pair's probes share.
    Clearance and overhead checks use a coarse copy (``coarse_m``) of the solid geometry, whose size
    grows with the site's area, not its density. Airborne snow and noise are left out of both."""

    def __init__(
        self,
        tiles: SceneTiles,
        skip_classes: np.ndarray,
        coarse_m: float = 0.25,
        lod_factor: float = 1.0,
        point_size_px: int = 1,
    ) -> None:
        self.tiles = tiles
        self.skip = np.asarray(skip_classes, dtype=np.uint8)
        self.lod_factor = lod_factor
        self.point_size_px = point_size_px
        self.points_read = 0
        self.reads = 0
        coarse = tiles.points(resolution=coarse_m, attributes=("class",))
        keep = ~np.isin(coarse.attributes["class"], self.skip)
        self._coarse = ArrayPointSource(coarse.xyz_m[keep].astype(np.float32))

    def points_for_view(self, camera: Camera, scale: float) -> np.ndarray:
        """(N, 3) float32 site-local metres: the points a probe of ``camera`` at ``scale`` draws."""
        out = self.tiles.points_for_view(
            camera, scale, attributes=("class",), lod_factor=self.lod_factor, point_size_px=self.point_size_px
        )
        self.points_read += out.stats.points_read
        self.reads += 1
        return out.xyz_m[~np.isin(out.attributes["class"], self.skip)].astype(np.float32)

    def nearest_distance(self, xyz: np.ndarray) -> np.ndarray:
        return self._coarse.nearest_distance(xyz)

    def count_above(self, xyz: np.ndarray, radius_m: float) -> np.ndarray:
        return self._coarse.count_above(xyz, radius_m)
