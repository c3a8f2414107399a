"""A published release of the small synthetic site, built once per test session (tests that add
versions or sites do so under other names)."""

from __future__ import annotations

import pytest
from sitehelpers import epoch_dirs, make_home

from siteline import pipeline
from siteline.catalog import open_catalog
from siteline.catalog.context import StageContext
from siteline.ingest.stage import ingest_mission
from siteline.pointpass import TilingResources
from siteline.records.params.pairs import PairParams
from siteline.records.params.release import ReleaseKnobs
from siteline.release.stage import publish_release
from siteline.tiles.stage import tile_scene

PARAMS = PairParams(scale=0.5, point_size_px=3, views=6, seed=0, min_coverage=0.3)
KNOBS = ReleaseKnobs.exactly(PARAMS)


@pytest.fixture(scope="session")
def built(tmp_path_factory, synth_site):
    settings = make_home(tmp_path_factory.mktemp("release"), site_dir=synth_site)
    cat = open_catalog(settings)
    for m in epoch_dirs(synth_site):
        r = ingest_mission(StageContext(cat, settings), m, "demo")
        tile_scene(StageContext(cat, settings), r.scene_id, resources=TilingResources(workers=1))
    info = pipeline.release(StageContext(cat, settings), "demo", "rel", KNOBS)
    pub = publish_release(StageContext(cat, settings), "rel", info.version)
    yield settings, cat, pub
    cat.dispose()
