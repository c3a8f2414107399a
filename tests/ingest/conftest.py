"""A small synthetic site shared by the ingest tests, and the settings of a migrated home with a site (``site_settings``)."""

from __future__ import annotations

import pytest
from sitehelpers import make_home

from siteline.catalog import open_catalog
from siteline.config import Settings


@pytest.fixture
def site_settings(tmp_path, synth_site) -> Settings:
    return make_home(tmp_path, site_dir=synth_site)


@pytest.fixture
def cat(site_settings):
    c = open_catalog(site_settings)
    yield c
    c.dispose()
