"""Migrations build exactly the ORM's schema, walk down to base and back up with data present."""

from __future__ import annotations

import pytest
import sqlalchemy as sa
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext

from siteline.catalog import Base, migrate, open_catalog
from siteline.catalog.engine import make_engine
from siteline.catalog.sites import add_site, list_sites
from siteline.errors import RevisionMismatchError
from siteline.site.spec import make_site_spec


def _diff(engine: sa.Engine) -> list:
    with engine.connect() as conn:
        ctx = MigrationContext.configure(conn, opts={"compare_type": True})
        return compare_metadata(ctx, Base.metadata)


def test_upgrade_matches_orm_metadata(db_url: str) -> None:
    engine = make_engine(db_url)
    migrate.upgrade(engine)
    assert migrate.current_revision(engine) == migrate.head_revision()
    assert _diff(engine) == []
    engine.dispose()


def test_downgrade_to_base_and_up_again_with_data(db_url: str) -> None:
    engine = make_engine(db_url)
    migrate.upgrade(engine)
    cat = open_catalog(db_url)
    with cat.transaction() as s:
        add_site(s, make_site_spec("a", "EPSG:32618", (445000.0, 5030000.0, 80.0)))
    cat.dispose()
    migrate.downgrade(engine, "base")
    assert migrate.current_revision(engine) is None
    tables = set(sa.inspect(engine).get_table_names()) - {"alembic_version"}
    assert tables == set()
    migrate.upgrade(engine)
    assert _diff(engine) == []
    cat = open_catalog(db_url)
    with cat.transaction() as s:
        assert list_sites(s) == []
        add_site(s, make_site_spec("b", "EPSG:32618", (0.0, 0.0, 0.0)))
    cat.dispose()
    engine.dispose()


def test_refuses_uninitialised_database(db_url: str) -> None:
    with pytest.raises(RevisionMismatchError, match="siteline init"):
        open_catalog(db_url)


def test_refuses_foreign_revision(db_url: str) -> None:
    engine = make_engine(db_url)
    migrate.upgrade(engine)
    with engine.begin() as conn:
        conn.execute(sa.text("UPDATE alembic_version SET version_num = 'ffffdeadbeef'"))
    with pytest.raises(RevisionMismatchError, match="ffffdeadbeef.*does not know"):
        open_catalog(db_url)
    engine.dispose()


def test_refuses_empty_version_table(db_url: str) -> None:
    engine = make_engine(db_url)
    migrate.upgrade(engine)
    with engine.begin() as conn:
        conn.execute(sa.text("DELETE FROM alembic_version"))
    with pytest.raises(RevisionMismatchError, match="not initialised"):
        open_catalog(db_url)
    engine.dispose()


def test_sqlite_uses_wal_and_foreign_keys(sqlite_url: str) -> None:
    engine = make_engine(sqlite_url)
    with engine.connect() as conn:
        assert conn.execute(sa.text("PRAGMA journal_mode")).scalar() == "wal"
        assert conn.execute(sa.text("PRAGMA foreign_keys")).scalar() == 1
    engine.dispose()


def test_label_set_versions_migrate_up_and_down_with_data(db_url: str) -> None:
    """0001 -> 0002 keeps version-1 rows (their classes are the tile store's); 0002 -> 0001 drops the
    imported versions' rows and columns and keeps version 1."""
    engine = make_engine(db_url)
    migrate.upgrade(engine, "0001")
    with engine.begin() as conn:
        conn.execute(sa.text(
            "INSERT INTO site (name, crs, origin_x, origin_y, origin_z, taxonomy, tile_size_m, created_at) "
            "VALUES ('a', 'EPSG:32618', 0, 0, 0, '{}', 50, CURRENT_TIMESTAMP)"
        ))  # fmt: skip
        conn.execute(sa.text(
            "INSERT INTO mission (site_id, manifest_sha256, name, received_at, status, storage, root_uri) "
            "VALUES (1, 'm', 'm', CURRENT_TIMESTAMP, 'ingested', 'copy', '/x')"
        ))  # fmt: skip
        conn.execute(sa.text(
            "INSERT INTO scene (site_id, mission_id, capture_time, point_count, bounds, registration, "
            "statistics, status, created_at) VALUES (1, 1, CURRENT_TIMESTAMP, 1, '{}', '{}', '{}', "
            "'registered', CURRENT_TIMESTAMP)"
        ))  # fmt: skip
        conn.execute(sa.text(
            "INSERT INTO label_set (scene_id, version, source, class_histogram, created_at) "
            "VALUES (1, 1, 'las', '{}', CURRENT_TIMESTAMP)"
        ))  # fmt: skip
    migrate.upgrade(engine)
    assert _diff(engine) == []
    with engine.begin() as conn:
        assert conn.execute(sa.text("SELECT version, uri FROM label_set")).all() == [(1, None)]
        conn.execute(sa.text(
            "INSERT INTO label_set (scene_id, version, source, class_histogram, created_at, uri, "
            "parent_version, changed_points) VALUES (1, 2, 'import f.laz', '{}', CURRENT_TIMESTAMP, "
            "'/x/v2.zarr', 1, 5)"
        ))  # fmt: skip
    migrate.downgrade(engine, "0001")
    with engine.begin() as conn:
        assert conn.execute(sa.text("SELECT version FROM label_set")).all() == [(1,)]
    assert "uri" not in {c["name"] for c in sa.inspect(engine).get_columns("label_set")}
    migrate.downgrade(engine, "base")
    engine.dispose()


def test_a_mission_goes_into_two_sites_after_0007_and_downgrade_says_what_blocks_it(db_url: str) -> None:
    """0006 -> 0007 keeps sites (at version 1) and missions; the same manifest may then be in two
    sites, and a downgrade back to one-site-per-manifest refuses while it is."""
    engine = make_engine(db_url)
    migrate.upgrade(engine, "0006")
    site = (
        "INSERT INTO site (name, crs, origin_x, origin_y, origin_z, taxonomy, tile_size_m, created_at) "
        "VALUES ('{}', 'EPSG:32618', 0, 0, 0, '{{}}', 50, CURRENT_TIMESTAMP)"
    )
    mission = (
        "INSERT INTO mission (site_id, manifest_sha256, name, received_at, status, storage, root_uri) "
        "VALUES ({}, 'm', 'm', CURRENT_TIMESTAMP, 'ingested', 'copy', '/x')"
    )
    with engine.begin() as conn:
        conn.execute(sa.text(site.format("a")))
        conn.execute(sa.text(site.format("b")))
        conn.execute(sa.text(mission.format(1)))
    migrate.upgrade(engine)
    assert _diff(engine) == []
    with engine.begin() as conn:
        assert conn.execute(sa.text("SELECT name, version FROM site ORDER BY name")).all() == [
            ("a", 1),
            ("b", 1),
        ]
        conn.execute(sa.text(mission.format(2)))
    with pytest.raises(Exception, match="ingested into several sites"):
        migrate.downgrade(engine, "0006")
    with engine.begin() as conn:
        conn.execute(sa.text("DELETE FROM mission WHERE site_id = 2"))
    migrate.downgrade(engine, "0006")
    migrate.downgrade(engine, "base")
    engine.dispose()
