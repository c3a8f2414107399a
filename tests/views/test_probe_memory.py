"""View generation's memory and reads stay flat when the scene's density quadruples, once the data are
denser than the probes' pixel footprints (DESIGN.md §6: a view reads what its pixels need). A scene
under TilePointSource's memory budget is read once, whole (bench/views.py measures that); these scenes
are read as one over it is (``memory_points=0``)."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pyproj
import pytest

from siteline.camera.pinhole import Camera
from siteline.pairs.sources import TilePointSource
from siteline.pointpass import TilingResources, write_las
from siteline.records.params.views import ViewParams
from siteline.site.spec import make_site_spec
from siteline.tiles.reader import SceneTiles
from siteline.tiles.writer import TileInput, write_tiles
from siteline.views.generate import NamedCamera, generate_views
from siteline.views.ground import fit_ground_plane

ORIGIN = (445_000.0, 5_030_000.0, 80.0)
# probes at 1/8 of 660 x 495 from 45-75 m: a pixel footprint of 0.7-1.2 m, so 30 points/m2 already beat it
PARAMS = ViewParams(
    scale=0.125,
    views=8,
    min_coverage=0.2,
    mirror=False,
    vertical_fractions=(1.0, 0.75),
    forward_fractions=(0.0, 0.25),
)


def _surfaces(density: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Ground 80 x 80 m and four 10 x 10 x 8 m blocks (roof and walls), ``density`` points per m2."""
    parts, classes = [], []
    n = int(density * 80 * 80)
    parts.append(np.c_[rng.uniform(-40, 40, (n, 2)), rng.normal(0, 0.02, n)])
    classes.append(np.full(n, 2))
    for cx, cy in ((-20, -20), (20, -20), (-20, 20), (20, 20)):
        n = int(density * 100)
        parts.append(np.c_[rng.uniform(cx - 5, cx + 5, n), rng.uniform(cy - 5, cy + 5, n), np.full(n, 8.0)])
        for axis, side in ((0, -5), (0, 5), (1, -5), (1, 5)):
            n = int(density * 80)
            wall = np.c_[rng.uniform(-5, 5, n), rng.uniform(-5, 5, n), rng.uniform(0, 8, n)]
            wall[:, axis] = side
            parts.append(wall + [cx, cy, 0])
        classes += [np.full(int(density * 100), 6)] + [np.full(int(density * 80), 6)] * 4
    return np.concatenate(parts), np.concatenate(classes).astype(np.uint8)


def _generate(tmp_path, density: float) -> dict:
    rng = np.random.default_rng(7)
    local, cls = _surfaces(density, rng)
    las = tmp_path / f"d{density:g}.las"
    write_las(las, local + np.asarray(ORIGIN), crs="EPSG:32618", classification=cls)
    site = make_site_spec("m", "EPSG:32618", ORIGIN)
    r = write_tiles(
        TileInput(las, site, pyproj.CRS("EPSG:32618")),
        tmp_path / f"d{density:g}.zarr",
        resources=TilingResources(workers=1),
    )
    index = SceneTiles.open(r.uri)
    tiles = SceneTiles(r.uri, index.nodes, index.spec, cache_bytes=4 * 2**20)  # a fixed cache budget
    plane = fit_ground_plane(local[cls == 2], seed=0)
    cams = [
        NamedCamera(f"c{k}", Camera.look_at((x, y, 60.0), (0, 0, 0), 660, 495, fx=500.0))
        for k, (x, y) in enumerate(((-30, -30), (30, -30), (-30, 30), (30, 30)))
    ]
    tracemalloc.start()
    source = TilePointSource(tiles, np.array([], np.uint8), memory_points=0)
    views = generate_views(cams, plane, None, source, PARAMS)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return {
        "points": len(local),
        "peak": peak,
        "per_probe": source.points_read / source.reads,
        "views": [(v.parent, v.strategy) for v in views.views],
    }


@pytest.mark.slow
def test_view_generation_memory_is_flat_in_density(tmp_path) -> None:
    sparse, dense = _generate(tmp_path, 30.0), _generate(tmp_path, 120.0)
    assert dense["points"] == pytest.approx(4 * sparse["points"], rel=0.01)
    assert dense["views"] == sparse["views"] and sparse["views"]
    assert dense["per_probe"] / sparse["per_probe"] < 1.3, (sparse, dense)
    assert dense["peak"] / sparse["peak"] < 1.3, (sparse, dense)
