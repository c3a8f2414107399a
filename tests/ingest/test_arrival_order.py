"""Missions arrive in any order: pairs follow capture order (a scene landing between two supersedes
their pair) and a scene's tile store depends on its content, not on its id or arrival order."""

from __future__ import annotations

from sitehelpers import epoch_dirs, make_home

from siteline.catalog import open_catalog
from siteline.catalog.context import StageContext
from siteline.catalog.pairs import list_pairs, pair_ids_of_scene
from siteline.catalog.sites import get_site
from siteline.ingest.stage import ingest_mission
from siteline.pointpass import TilingResources
from siteline.tiles.stage import tile_scene


def _home(tmp_path, synth_site, order: list[int], name: str):
    settings = make_home(tmp_path / name, site_dir=synth_site)
    cat = open_catalog(settings)
    ids = {}
    for e in order:
        ids[e] = ingest_mission(StageContext(cat, settings), epoch_dirs(synth_site)[e], "demo").scene_id
    return settings, cat, ids


def test_pairs_follow_capture_order_and_tiles_do_not_depend_on_arrival(tmp_path, synth_site) -> None:
    settings, cat, ids = _home(tmp_path, synth_site, [0, 2, 1], "late")
    with cat.transaction() as s:
        pairs = [(p.t1_scene_id, p.t2_scene_id) for p in list_pairs(s, get_site(s, "demo"))]
        around = pair_ids_of_scene(s, ids[0])
    assert pairs == [(ids[0], ids[1]), (ids[1], ids[2])]  # not (e00, e02)
    assert len(around) == 1
    late = tile_scene(StageContext(cat, settings), ids[1], resources=TilingResources(workers=1)).tiling
    cat.dispose()
    settings2, cat2, ids2 = _home(tmp_path, synth_site, [1], "alone")
    alone = tile_scene(StageContext(cat2, settings2), ids2[1], resources=TilingResources(workers=1)).tiling
    cat2.dispose()
    assert ids[1] != ids2[1]  # scene 3 there, scene 1 here
    assert late is not None and alone is not None and late.checksum == alone.checksum
