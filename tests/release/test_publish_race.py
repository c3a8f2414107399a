"""A build that raced the ingest of a middle scene is never published: its pair was superseded by the
two pairs through the new scene while it was built (an attack run published e00 -> e02 3 of 3 times)."""

from __future__ import annotations

import pytest
from sitehelpers import epoch_dirs, ingest_and_tile, make_home

from siteline import pipeline
from siteline.catalog import open_catalog
from siteline.errors import ReleaseError
from siteline.ingest.stage import ingest_mission
from siteline.release.stage import publish_release

from .conftest import KNOBS


def test_a_draft_whose_pair_was_superseded_is_not_published(tmp_path, synth_site) -> None:
    settings = make_home(tmp_path, site_dir=synth_site)
    cat = open_catalog(settings)
    e0, e1, e2 = epoch_dirs(synth_site)
    ingest_and_tile(cat, settings, [e0, e2])
    draft = pipeline.release(cat, settings, "demo", "race", KNOBS)  # the pair e00 -> e02
    ingest_mission(cat, settings, e1, "demo")  # the middle scene lands before the publish
    with pytest.raises(ReleaseError, match="superseded since.*Build it again"):
        publish_release(cat, settings, "race", draft.version)
    assert not (settings.home / "releases" / "race" / draft.version).exists()
    cat.dispose()


def test_a_publish_racing_the_ingest_of_a_middle_scene_is_refused_when_it_is_recorded(tmp_path, synth_site, monkeypatch) -> None:
    """The middle scene's ingest commits after the publish planned (checked its pairs) and before it
    records: the publish checks again, under the site's row lock, in the transaction that records it,
    and moves the draft back (an attack with a 60 s window published 1.0.0 on e00 -> e02)."""
    from siteline.release import stage

    settings = make_home(tmp_path, site_dir=synth_site)
    cat = open_catalog(settings)
    e0, e1, e2 = epoch_dirs(synth_site)
    ingest_and_tile(cat, settings, [e0, e2])
    draft = pipeline.release(cat, settings, "demo", "race", KNOBS)
    moved = stage.move_into_place

    def move_then_ingest(plan):  # noqa: ANN001, ANN202  (the window: checksums verified, folder renamed)
        moved(plan)
        ingest_mission(cat, settings, e1, "demo")

    monkeypatch.setattr(stage, "move_into_place", move_then_ingest)
    with pytest.raises(ReleaseError, match="superseded since.*Build it again"):
        publish_release(cat, settings, "race", draft.version)
    assert not (settings.home / "releases" / "race" / draft.version).exists()
    assert (settings.home / "releases" / "race" / ".drafts" / draft.version / "manifest.json").exists()
    with cat.transaction() as s:
        from siteline.catalog.releases import get_release

        assert get_release(s, "race", draft.version).status == "draft"
    cat.dispose()
