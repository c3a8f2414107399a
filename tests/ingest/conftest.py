"""A small synthetic site shared by the ingest tests, and a migrated home with a site."""

from __future__ import annotations

import pytest
from sitehelpers import make_home

from siteline.catalog import open_catalog
from siteline.config import Settings


@pytest.fixture
def home(tmp_path, synth_site) -> Settings:
    return make_home(tmp_path, site_dir=synth_site)


@pytest.fixture
def cat(home):
    c = open_catalog(home)
    yield c
    c.dispose()
