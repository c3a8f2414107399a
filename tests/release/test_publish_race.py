"""A build that raced the ingest of a middle scene is never published: its pair was superseded by the
two pairs through the new scene while it was built (an attack run published e00 -> e02 3 of 3 times)."""

from __future__ import annotations

import pytest
from sitehelpers import epoch_dirs, ingest_and_tile, make_home

from siteline import pipeline
from siteline.catalog import open_catalog
from siteline.catalog.context import StageContext
from siteline.errors import ReleaseError
from siteline.ingest.stage import ingest_mission
from siteline.release.stage import publish_release

from .conftest import KNOBS


def test_a_draft_whose_pair_was_superseded_is_not_published(tmp_path, synth_site) -> None:
    settings = make_home(tmp_path, site_dir=synth_site)
    cat = open_catalog(settings)
    e0, e1, e2 = epoch_dirs(synth_site)
    ingest_and_tile(cat, settings, [e0, e2])
    draft = pipeline.release(StageContext(cat, settings), "demo", "race", KNOBS)  # the pair e00 -> e02
    ingest_mission(StageContext(cat, settings), e1, "demo")  # the middle scene lands before the publish
    with pytest.raises(ReleaseError, match="superseded since.*Build it again"):
        publish_release(StageContext(cat, settings), "race", draft.version)
    assert not (settings.home / "releases" / "race" / draft.version).exists()
    cat.dispose()


def test_a_publish_racing_the_ingest_of_a_middle_scene_is_refused_when_it_is_recorded(
    tmp_path, synth_site, monkeypatch
) -> None:
    """The middle scene's ingest commits after the publish planned (checked its pairs) and before it
    records: the publish checks again, under the site's row lock, in the transaction that records it,
    and moves the draft back (an attack with a 60 s window published 1.0.0 on e00 -> e02)."""
    from siteline.release import stage

    settings = make_home(tmp_path, site_dir=synth_site)
    cat = open_catalog(settings)
    e0, e1, e2 = epoch_dirs(synth_site)
    ingest_and_tile(cat, settings, [e0, e2])
    draft = pipeline.release(StageContext(cat, settings), "demo", "race", KNOBS)
    moved = stage.move_into_place

    def move_then_ingest(plan):  # noqa: ANN001, ANN202  (the window: checksums verified, folder renamed)
        moved(plan)
        ingest_mission(StageContext(cat, settings), e1, "demo")

    monkeypatch.setattr(stage, "move_into_place", move_then_ingest)
    with pytest.raises(ReleaseError, match="superseded since.*Build it again"):
        publish_release(StageContext(cat, settings), "race", draft.version)
    assert not (settings.home / "releases" / "race" / draft.version).exists()
    assert (settings.home / "releases" / "race" / ".drafts" / draft.version / "manifest.json").exists()
    with cat.transaction() as s:
        from siteline.catalog.releases import get_release

        assert get_release(s, "race", draft.version).status == "draft"
    cat.dispose()


@pytest.mark.parametrize("engine", ["sqlite", "postgresql"])
def test_an_ingest_committing_inside_the_publish_waits_for_it_on_both_engines(
    tmp_path, synth_site, monkeypatch, request, engine
) -> None:
    """The window the re-check leaves: an ingest of the middle scene that tries to commit after the
    publish re-checked its pairs and before the publish commits. It must wait for the publish (the
    site's row lock, a write lock on SQLite, held across both), so the release is published from pairs
    current when it was recorded and the ingest supersedes them afterwards. On SQLite, where SELECT ...
    FOR UPDATE is ignored, the ingest used to commit inside the window: 1.0.0 published on a pair that
    was already superseded."""
    import threading

    from siteline.catalog import releases

    url = None if engine == "sqlite" else request.getfixturevalue("postgres_url")
    settings = make_home(tmp_path, url=url, site_dir=synth_site)
    cat = open_catalog(settings)
    e0, e1, e2 = epoch_dirs(synth_site)
    ingest_and_tile(cat, settings, [e0, e2])
    draft = pipeline.release(StageContext(cat, settings), "demo", "race", KNOBS)
    events: list[str] = []
    ingest = threading.Thread(
        target=lambda: (
            ingest_mission(StageContext(cat, settings), e1, "demo"),
            events.append("ingest committed"),
        )
    )
    checked = releases.refuse_superseded

    def check_then_let_the_ingest_run(session, rel):  # noqa: ANN001, ANN202  (the window, widened)
        checked(session, rel)
        ingest.start()
        ingest.join(timeout=8.0)  # an ingest free to commit does so well within this
        events.append("publish recording")

    monkeypatch.setattr(releases, "refuse_superseded", check_then_let_the_ingest_run)
    try:
        publish_release(StageContext(cat, settings), "race", draft.version)
        events.append("publish committed")
    finally:
        ingest.join(timeout=120)
    assert events == ["publish recording", "publish committed", "ingest committed"], events
    with cat.transaction() as s:
        from siteline.catalog.pairs import pair_ids_of_scene  # noqa: F401  (the ingest's pairs exist)
        from siteline.catalog.releases import get_release

        assert get_release(s, "race", draft.version).status == "published"
    cat.dispose()
