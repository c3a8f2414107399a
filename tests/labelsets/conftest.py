"""Two tiled scenes of the small synthetic site in a home of their own (label-set versions are added
by the tests of this package, so nothing here is shared with other packages)."""

from __future__ import annotations

import pytest
from sitehelpers import epoch_dirs, make_home

from siteline.catalog import open_catalog
from siteline.ingest.mission import ingest_mission
from siteline.tiles import tile_scene


@pytest.fixture(scope="package")
def scenes(tmp_path_factory, synth_site):
    settings = make_home(tmp_path_factory.mktemp("labelsets"), site_dir=synth_site)
    cat = open_catalog(settings)
    for m in epoch_dirs(synth_site)[:2]:
        r = ingest_mission(cat, settings, m, "demo")
        tile_scene(cat, settings, r.scene_id, workers=1)
    yield settings, cat
    cat.dispose()
