"""A small synthetic site shared by the ingest tests, and a migrated home with a site."""

from __future__ import annotations

from pathlib import Path

import pytest
from sitehelpers import SYNTH, make_home

from siteline.catalog import open_catalog
from siteline.config import Settings
from siteline.synth import write_site


@pytest.fixture(scope="session")
def synth_site(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("synth-ingest")
    write_site(out, SYNTH)
    return out


@pytest.fixture
def home(tmp_path, synth_site) -> Settings:
    return make_home(tmp_path, site_dir=synth_site)


@pytest.fixture
def cat(home):
    c = open_catalog(home)
    yield c
    c.dispose()
