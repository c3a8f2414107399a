"""Points on and within a quantum of tile edges: the tile store may hold such a point in one tile while
its exported position falls in the neighbour; the import still matches each exactly once."""

from __future__ import annotations

import itertools

import laspy
import numpy as np

from siteline.labelsets.execute import SPILL_DTYPE, _match_tiles, _spill
from siteline.labelsets.plan import ImportPlan
from siteline.pointpass import TilingResources, write_las
from siteline.progress import no_progress
from siteline.records import LabelSetRef, TileSource
from siteline.records.labelsets import ExportedLabels
from siteline.site.spec import make_site_spec
from siteline.tiles.export import export_las
from siteline.tiles.reader import SceneTiles
from siteline.tiles.writer import TileInput, write_tiles

ORIGIN = (500_000.0, 4_000_000.0, 10.0)


def test_points_at_tile_edges_match_once(tmp_path) -> None:
    site = make_site_spec("edges", "EPSG:32618", ORIGIN)
    size = site.tile_size_m
    near = [-0.0006, -0.0004, -0.0001, 0.0, 0.0001, 0.0004, 0.0006]  # around the edges, 0.1 mm steps
    xs = [e + k * size for k in (0, 1) for e in near] + [25.0]
    local = np.array([(x, y, 1.0) for x, y in itertools.product(xs, xs)])
    n = len(local)
    las = tmp_path / "edges.las"
    write_las(
        las, local + np.array(ORIGIN), crs=site.crs, scale=0.0001,
        classification=np.full(n, 2, np.uint8), gps_time=np.arange(n) * 0.5,
        return_number=np.ones(n, np.uint8), intensity=np.zeros(n, np.uint16),
    )  # fmt: skip
    store = tmp_path / "tiles.zarr"
    write_tiles(TileInput(las, site, site.pyproj_crs), store, resources=TilingResources(workers=1))
    tiles = SceneTiles.open(store)
    assert tiles.point_count == n and len(tiles.by_tile) >= 9

    out = tmp_path / "export.las"
    export_las(tiles, site, out, labels=ExportedLabels("edges", 7, None))
    edited = laspy.read(out)
    edited.classification = np.full(n, 2, np.uint8)  # every ground point (site id 1) becomes building
    edited.points = edited.points[np.random.default_rng(1).permutation(n)]
    edited.write(tmp_path / "edited.las")

    spill = tmp_path / "spill"
    spill.mkdir()
    plan = ImportPlan(7, site, TileSource(str(store), tiles.spec), LabelSetRef(7, 1, None, "las"), 2)
    n_file, has_time, unknown = _spill(
        tmp_path / "edited.las", plan, tiles, site.taxonomy.id_lut(), spill, no_progress
    )
    assert n_file == n and has_time and not unknown.any()
    spilled = sum(len(np.fromfile(p, SPILL_DTYPE)) for p in spill.iterdir())
    assert spilled > n  # points near an edge went to both tiles
    result = _match_tiles(tiles, spill, has_time, tmp_path / "labels.zarr", site, n_file, no_progress)
    assert result.matched == n and result.unmatched == result.duplicated == result.untouched == 0
    assert result.changes == {"ground->building": n}
