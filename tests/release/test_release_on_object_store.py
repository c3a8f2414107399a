"""The same release built with every store on an object store (a local S3 server) instead of a folder."""

from __future__ import annotations

from pathlib import Path

import sqlalchemy as sa
from sitehelpers import epoch_dirs, make_home

from siteline import stores
from siteline.catalog import open_catalog
from siteline.catalog.models import Render, Scene
from siteline.ingest.mission import ingest_mission
from siteline.release import build_release, publish_release, read_manifest, verify_files
from siteline.tiles import tile_scene

from .conftest import PARAMS


def test_release_on_s3_matches_the_local_one(built, tmp_path, synth_site, s3_store) -> None:
    _, _, local = built
    settings = make_home(tmp_path, site_dir=synth_site, store_url=s3_store)
    cat = open_catalog(settings)
    try:
        for m in epoch_dirs(synth_site):
            r = ingest_mission(cat, settings, m, "demo")
            tile_scene(cat, settings, r.scene_id, workers=1)
        info = build_release(cat, settings, "demo", "rel", PARAMS)
        pub = publish_release(cat, settings, "rel", info.version)
        with cat.transaction() as s:
            uris = [sc.tile_store_uri for sc in s.execute(sa.select(Scene)).scalars()]
            paths = [r.paths["image"] for r in s.execute(sa.select(Render)).scalars()]
    finally:
        cat.dispose()
    assert uris and all(u.startswith(f"{s3_store}/tiles/") and stores.is_complete(u) for u in uris)
    assert paths and all(p.startswith(f"{s3_store}/pairs/") and stores.exists(p) for p in paths)
    assert not (settings.home / "stores").exists()  # nothing went to the local folder
    assert verify_files(Path(pub.root)) == []

    def contents(root: str) -> dict[str, str]:
        doc = read_manifest(Path(root))
        return {f["path"]: f["sha256"] for f in doc["files"] if f["path"].endswith((".png", "stats.json"))}

    assert contents(pub.root) == contents(local.root)
    assert (
        read_manifest(Path(pub.root))["lineage"]["scenes"]
        == read_manifest(Path(local.root))["lineage"]["scenes"]
    )
