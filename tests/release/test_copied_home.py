"""A SITELINE_HOME copied elsewhere (``cp -a home home2``) reads and writes its own stores: the
catalog records store addresses relative to the home and the store root, and ``release verify``
names the folder it checked."""

from __future__ import annotations

import shutil
import sqlite3
import subprocess
from pathlib import Path

import sqlalchemy as sa
from sitehelpers import make_home, run_exe

from siteline.catalog import migrate, open_catalog, store_roots
from siteline.catalog.addresses import Roots, rooted
from siteline.catalog.engine import make_engine
from siteline.records.release import Manifest


def _dump(db: Path) -> str:
    con = sqlite3.connect(db)
    try:
        return "\n".join(con.iterdump())
    finally:
        con.close()


def test_a_copied_home_checks_its_own_release(built, tmp_path):
    settings, cat, pub = built
    home = settings.home
    copy = tmp_path / "home2"
    subprocess.run(["cp", "-a", str(home), str(copy)], check=True)

    dump = _dump(copy / "catalog.sqlite")
    assert str(home) not in dump, "the catalog records an absolute path of the home"
    assert "store:tiles/" in dump and "home:releases/" in dump

    ok = run_exe(copy, "release", "verify", "rel", pub.version)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    assert f"checked {copy.resolve()}" in ok.stdout

    shown = run_exe(copy, "scene", "show", "1", "--json")
    assert shown.returncode == 0, shown.stderr
    assert f'"{copy.resolve()}/stores/tiles/' in shown.stdout

    published = copy / "releases" / "rel" / pub.version
    for split in ("train", "val", "test"):
        shutil.rmtree(published / split / "A", ignore_errors=True)
    (published / "manifest.json").unlink()
    bad = run_exe(copy, "release", "verify", "rel", pub.version)
    assert bad.returncode == 1, bad.stdout + bad.stderr
    assert f"checked {copy.resolve()}" in bad.stdout and "manifest.json" in bad.stdout

    # the original is untouched and still whole
    orig = run_exe(home, "release", "verify", "rel", pub.version)
    assert orig.returncode == 0, orig.stdout + orig.stderr


def test_migration_makes_recorded_addresses_relative(tmp_path):
    """A catalog written before the rule (absolute addresses) is rewritten by `db upgrade` under its
    settings' roots, and written absolute again by a downgrade."""
    settings = make_home(tmp_path)
    engine = make_engine(settings.database_url)
    roots = store_roots(settings)
    tiles = f"{roots.store}/tiles/scene-1.zarr"
    elsewhere = "/data/survey/mission-7"
    migrate.downgrade(engine, "0007", roots)
    with engine.begin() as conn:
        conn.execute(sa.text(
            "INSERT INTO mission (id, site_id, manifest_sha256, name, received_at, status, storage, root_uri) "
            "VALUES (1, 1, :sha, 'm', '2026-01-01', 'received', 'reference', :root)"
        ), {"sha": "0" * 64, "root": elsewhere})  # fmt: skip
        conn.execute(sa.text(
            "INSERT INTO scene (id, site_id, mission_id, capture_time, point_count, bounds, registration, "
            "statistics, tile_store_uri, status, created_at) VALUES (1, 1, 1, '2026-01-01', 10, '{}', '{}', "
            ":stats, :uri, 'tiled', '2026-01-01')"
        ), {"stats": f'{{"tiles": {{"uri": "{tiles}"}}}}', "uri": tiles})  # fmt: skip
    migrate.upgrade(engine, "head", roots)
    with engine.connect() as conn:
        row = conn.execute(sa.text("SELECT tile_store_uri, statistics FROM scene")).one()
        mission_root = conn.execute(sa.text("SELECT root_uri FROM mission")).scalar_one()
    assert row[0] == "store:tiles/scene-1.zarr" and "store:tiles/scene-1.zarr" in row[1]
    assert mission_root == elsewhere  # outside both roots: kept absolute

    cat = open_catalog(settings)
    with cat.transaction() as s:
        assert s.execute(sa.text("SELECT 1")).scalar_one() == 1
        from siteline.catalog.models import Scene

        assert s.get(Scene, 1).tile_store_uri == tiles
    cat.dispose()

    migrate.downgrade(engine, "0007", Roots(roots.store, roots.home))
    with engine.connect() as conn:
        assert conn.execute(sa.text("SELECT tile_store_uri FROM scene")).scalar_one() == tiles
    with rooted(None):
        migrate.upgrade(engine, "head")  # without roots: left absolute, still read as written
    with engine.connect() as conn:
        assert conn.execute(sa.text("SELECT tile_store_uri FROM scene")).scalar_one() == tiles
    engine.dispose()


def test_a_copied_home_shows_a_pair_in_3d_with_the_original_gone(built, tmp_path):
    """The manifest records the change labels relative to the store (``store:labels/...``), never
    the building home's folder: a copy's 3D viewer reads its own stores, the original moved away."""
    import json

    from siteline import pipeline
    from siteline.config import Settings, sqlite_url

    settings, _, pub = built
    home = settings.home
    copy = tmp_path / "home2"
    subprocess.run(["cp", "-a", str(home), str(copy)], check=True)
    doc = json.loads((copy / "releases" / "rel" / pub.version / "manifest.json").read_text())
    assert str(home) not in json.dumps(doc), "the manifest names the building home's folder"
    assert all(p["labels"]["uri"].startswith("store:labels/") for p in doc["lineage"]["pairs"])

    def strings(x):  # noqa: ANN001, ANN202
        if isinstance(x, dict):
            for v in x.values():
                yield from strings(v)
        elif isinstance(x, list):
            for v in x:
                yield from strings(v)
        elif isinstance(x, str):
            yield x

    assert [t for t in strings(doc) if t.startswith("/")] == []
    away = tmp_path / "original-moved-away"
    home.rename(away)
    try:
        mine = Settings(home=copy, database_url=sqlite_url(copy / "catalog.sqlite"))
        cat = open_catalog(mine)
        try:
            pair = int(doc["lineage"]["pairs"][0]["id"])
            cloud = pipeline.pair_cloud(cat, mine, Manifest.from_dict(doc), pair)
            assert cloud.pair_id == pair
        finally:
            cat.dispose()
    finally:
        away.rename(home)


def test_verify_refuses_a_manifest_with_an_absolute_path(built, tmp_path):
    import json

    from sitehelpers import writable_copy

    from siteline.release.manifest import verify_files

    _, _, pub = built
    copy = writable_copy(pub.root, tmp_path / "copy")
    doc = json.loads((copy / "manifest.json").read_text())
    doc["lineage"]["pairs"][0]["labels"]["uri"] = "/home/someone/siteline/stores/labels/pair-1.zarr"
    (copy / "manifest.json").write_text(json.dumps(doc))
    problems = verify_files(copy)
    assert any("absolute path" in p and "lineage.pairs[0].labels.uri" in p for p in problems), problems
