"""Versions that mean something: a build that only adds pairs is a minor version whose earlier items
are unchanged and keep their splits; an item changed is a major one."""

from __future__ import annotations

import json
from pathlib import Path

from sitehelpers import epoch_dirs, ingest_and_tile, make_home

from siteline import pipeline
from siteline.catalog import open_catalog
from siteline.catalog.context import StageContext
from siteline.release.stage import publish_release

from .conftest import KNOBS


def _manifest(info) -> dict:  # noqa: ANN001
    return json.loads((Path(info.root) / "manifest.json").read_text())


def test_added_pairs_are_a_minor_version_and_move_no_item(tmp_path, synth_site) -> None:
    settings = make_home(tmp_path, site_dir=synth_site)
    cat = open_catalog(settings)
    e0, e1, e2 = epoch_dirs(synth_site)
    ingest_and_tile(cat, settings, [e0, e1])
    first = publish_release(
        StageContext(cat, settings),
        "ver",
        pipeline.release(StageContext(cat, settings), "demo", "ver", KNOBS).version,
    )
    ingest_and_tile(cat, settings, [e2])
    second = pipeline.release(StageContext(cat, settings), "demo", "ver", KNOBS)
    assert second.version == "1.1.0" and second.reason.startswith("new items only (pairs added: 2")
    a, b = _manifest(first), _manifest(second)
    before = {it["id"]: it["split"] for it in a["items"]}
    after = {it["id"]: it["split"] for it in b["items"]}
    assert before and all(after.get(i) == s for i, s in before.items())  # every item kept, same split
    files_a = {f["path"]: f["sha256"] for f in a["files"]}
    files_b = {f["path"]: f["sha256"] for f in b["files"]}
    assert all(files_b[p] == h for p, h in files_a.items() if p.endswith(".png") and "montage" not in p)
    assert {it["pair"] for it in b["items"]} == {1, 2}
    published = publish_release(StageContext(cat, settings), "ver", second.version)
    from siteline.release.query import diff_releases

    with cat.transaction() as s:
        d = diff_releases(s, "ver", "1.0.0", "1.1.0")
    assert d["why"].startswith("new items only") and d["pairs"]["added"] == [2]
    assert "Version 1.1.0: new items only" in (Path(published.root) / "README.md").read_text()
    cat.dispose()
