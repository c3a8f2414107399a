"""Scene geometry for view generation, served from the tile store."""

from __future__ import annotations

import numpy as np

from siteline.cameras import Camera
from siteline.tiles.reader import SceneTiles
from siteline.views.sources import ArrayPointSource


class TilePointSource:
    """A :class:`siteline.views.PointSource` over a tiled scene for view generation, which renders
    hundreds of probes per real camera: they all draw on one in-memory copy of the scene read once at
    ``probe_m`` spacing (depth and coverage probes need no finer), and clearance and overhead checks
    on a coarse copy (``coarse_m``) of its solid geometry (airborne snow and noise left out)."""

    def __init__(
        self, tiles: SceneTiles, skip_classes: np.ndarray, coarse_m: float = 0.25, probe_m: float = 0.05
    ) -> None:
        self.tiles = tiles
        probe = tiles.points(resolution=probe_m, attributes=("class",))
        self._probe = probe["xyz"][~np.isin(probe["class"], skip_classes)]
        coarse = tiles.points(resolution=coarse_m, attributes=("class",))
        keep = ~np.isin(coarse["class"], skip_classes)
        self._coarse = ArrayPointSource(coarse["xyz"][keep])

    def points_for_view(self, camera: Camera, scale: float) -> np.ndarray:
        return self._probe

    def nearest_distance(self, xyz: np.ndarray) -> np.ndarray:
        return self._coarse.nearest_distance(xyz)

    def count_above(self, xyz: np.ndarray, radius_m: float) -> np.ndarray:
        return self._coarse.count_above(xyz, radius_m)
