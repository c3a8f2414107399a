"""Engines and sessions for the catalog: SQLite (WAL, foreign keys) or PostgreSQL."""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import sqlalchemy as sa
from sqlalchemy import event
from sqlalchemy.engine import make_url
from sqlalchemy.orm import Session, sessionmaker

import siteline.catalog.guards  # noqa: F401  (registers the flush guards)
from siteline.errors import CatalogError
from siteline.stores.diskspace import error_chain, sqlite_code

# how long a writer waits for a SQLite catalog another writer holds (seconds; SITELINE_CATALOG_WAIT_S)
CATALOG_WAIT_S = 30.0


def catalog_wait_s() -> float:
    """Seconds a SQLite writer waits for the catalog: SITELINE_CATALOG_WAIT_S, else
    :data:`CATALOG_WAIT_S`; :class:`CatalogError` when it is not a number of seconds."""
    raw = os.environ.get("SITELINE_CATALOG_WAIT_S")
    if raw is None:
        return CATALOG_WAIT_S
    try:
        wait = float(raw)
    except ValueError:
        wait = -1.0
    if not 0 <= wait < 86400:
        raise CatalogError(f"SITELINE_CATALOG_WAIT_S={raw!r}: a number of seconds from 0 to 86400.")
    return wait


# SQLite's codes for a database another connection holds (SQLITE_BUSY, SQLITE_LOCKED)
_SQLITE_BUSY = (5, 6)


def catalog_busy(exc: BaseException) -> bool:
    """Whether ``exc`` (or an exception it was raised from) is SQLite's "database is locked": another
    writer held the catalog past the wait (told by SQLite's code, not its words)."""
    return any(sqlite_code(e) in _SQLITE_BUSY for e in error_chain(exc))


def catalog_busy_message() -> str:
    """One line for a command whose catalog write waited its whole wait behind another writer."""
    return (
        f"the catalog was held by another writer (a publish, an ingest or a build) for {catalog_wait_s():g} s, "
        "longer than this command waits (SITELINE_CATALOG_WAIT_S): nothing of this run was stored; "
        "run it again when the other one has finished."
    )


def _sqlite_pragmas(dbapi_connection: Any, connection_record: Any) -> None:
    cur = dbapi_connection.cursor()
    cur.execute("PRAGMA foreign_keys=ON")
    cur.execute("PRAGMA journal_mode=WAL")
    cur.execute("PRAGMA synchronous=NORMAL")
    cur.execute(f"PRAGMA busy_timeout={int(catalog_wait_s() * 1000)}")
    cur.close()


def make_engine(url: str) -> sa.Engine:
    """An engine for ``url``; a SQLite file's folder is created, WAL mode and foreign keys are on."""
    try:
        parsed = make_url(url)
    except sa.exc.ArgumentError as exc:
        raise CatalogError(f"catalog URL {url!r} is malformed: {exc}") from exc
    if parsed.get_backend_name() == "sqlite":
        if parsed.database and parsed.database != ":memory:":
            Path(parsed.database).parent.mkdir(parents=True, exist_ok=True)
        engine = sa.create_engine(url, connect_args={"timeout": catalog_wait_s()})
        event.listen(engine, "connect", _sqlite_pragmas)
        return engine
    if parsed.get_backend_name() == "postgresql" and parsed.get_driver_name() in ("", "psycopg2"):
        # psycopg 3 is the driver we ship; a bare postgresql:// URL would ask for psycopg2.
        parsed = parsed.set(drivername="postgresql+psycopg")
    try:
        return sa.create_engine(parsed, pool_pre_ping=True)
    except (sa.exc.NoSuchModuleError, ImportError) as exc:
        raise CatalogError(
            f"catalog URL {url!r}: no database driver for {parsed.drivername!r} ({exc}); use "
            "sqlite:///PATH or postgresql+psycopg://USER@HOST/DB."
        ) from exc


def ping(engine: sa.Engine) -> None:
    """Connect once; :class:`CatalogError` naming the URL (password hidden) when that fails."""
    try:
        with engine.connect() as conn:
            conn.execute(sa.text("SELECT 1"))
    except sa.exc.OperationalError as exc:
        raise CatalogError(
            f"cannot reach the catalog at {engine.url.render_as_string(hide_password=True)}: {exc.orig}"
        ) from exc


@contextmanager
def transaction(factory: sessionmaker[Session]) -> Iterator[Session]:
    """A session that commits when the block ends normally and rolls back otherwise."""
    session = factory()
    try:
        yield session
        session.commit()
    except BaseException:
        session.rollback()
        raise
    finally:
        session.close()
