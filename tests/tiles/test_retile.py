"""Re-tiling a scene whose store keeps input order inside its nodes: the CLI says how, `--retile` writes the
current layout beside the old store and swaps it in, and the scene's pairs are processed again instead
of reusing outputs aligned with the old order."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from siteline.catalog import open_catalog
from siteline.catalog.context import StageContext
from siteline.catalog.models import Scene
from siteline.catalog.scenes import tile_source
from siteline.pairs.stage import find_pair_output, process_pair
from siteline.pointpass import TilingResources
from siteline.records.params.pairs import PairParams
from siteline.records.tiling import TileSpec
from siteline.tiles.reader import SceneTiles
from siteline.tiles.stage import tile_scene

EXE = Path(sys.executable).with_name("siteline")
# one candidate per real camera: the test needs outputs, not a good view sample
ONE = {"vertical_fractions": [1.0], "forward_fractions": [0.0], "mirror": False}
PARAMS = PairParams(views=2, scale=0.125, min_coverage=0.1, min_valid=0.0, view_params=ONE)


def _exe(settings, *argv: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if not k.startswith("SITELINE_")}
    env |= {"SITELINE_HOME": str(settings.home), "SITELINE_DATABASE_URL": settings.database_url}
    return subprocess.run([str(EXE), *argv], env=env, capture_output=True, text=True, timeout=300)


def _points(cat, scene_id: int) -> tuple[str, np.ndarray]:
    with cat.transaction() as s:
        tiles = SceneTiles.from_source(tile_source(s, scene_id))
    pts = tiles.points(attributes=("gps_time",))
    return tiles.uri, np.sort(pts.attributes["gps_time"])


def test_retile_swaps_in_the_current_layout(tmp_path, synth_site) -> None:
    from sitehelpers import epoch_dirs, make_home

    from siteline.ingest.stage import ingest_mission

    settings = make_home(tmp_path, site_dir=synth_site)
    cat = open_catalog(settings)
    ids = [
        ingest_mission(StageContext(cat, settings), m, "demo").scene_id for m in epoch_dirs(synth_site)[:2]
    ]
    tile_scene(
        StageContext(cat, settings),
        ids[0],
        resources=TilingResources(workers=1),
        spec=TileSpec(node_order="input"),
    )  # as an old store
    tile_scene(StageContext(cat, settings), ids[1], resources=TilingResources(workers=1))
    before = process_pair(StageContext(cat, settings), 1, PARAMS)
    old_uri, old_points = _points(cat, ids[0])

    hint = tile_scene(StageContext(cat, settings), ids[0]).message
    assert "nothing to do" in hint and f"`siteline scene tile {ids[0]} --retile`" in hint

    done = _exe(settings, "scene", "tile", str(ids[0]), "--retile")
    assert done.returncode == 0 and "re-tiled" in done.stdout, done.stderr
    new_uri, new_points = _points(cat, ids[0])
    assert new_uri != old_uri and not Path(old_uri).exists()
    assert np.array_equal(new_points, old_points)  # the same points, in the current layout
    with cat.transaction() as s:
        stats = s.get(Scene, ids[0]).statistics["tiles"]
    assert stats["spec"]["node_order"] == "reversed-morton" and stats["generation"] == 1

    again = tile_scene(StageContext(cat, settings), ids[0]).message
    assert "nothing to do" in again and "--retile" not in again

    # outputs aligned with the old order are not reused (process_pair makes new ones); they stay for old releases
    assert find_pair_output(cat, settings, 1, PARAMS) is None and Path(before.root).exists()
    cat.dispose()
