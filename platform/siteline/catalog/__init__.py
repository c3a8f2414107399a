"""The SQL catalog: ORM models, migrations, sessions and query functions (DESIGN.md §8)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass

import sqlalchemy as sa
from sqlalchemy.orm import Session, sessionmaker

from siteline.catalog.addresses import Roots, rooted
from siteline.catalog.base import Base
from siteline.catalog.engine import make_engine, ping, transaction
from siteline.config import Settings

__all__ = ["Base", "Catalog", "open_catalog", "store_roots"]


@dataclass
class Catalog:
    """A catalog database: its engine and session factory, and the roots its store addresses are
    recorded against (None when opened from a bare URL: addresses recorded as given)."""

    engine: sa.Engine
    sessions: sessionmaker[Session]
    roots: Roots | None = None

    @contextmanager
    def transaction(self) -> Iterator[Session]:
        """A session committed at the end of the block, rolled back on error."""
        with rooted(self.roots), transaction(self.sessions) as session:
            yield session

    def lock(self, name: str, timeout_s: float | None = None) -> AbstractContextManager[None]:
        """Hold the named lock for the block, across processes and machines (siteline.catalog.locks)."""
        from siteline.catalog.locks import exclusive

        return exclusive(self.engine, name, timeout_s)

    def dispose(self) -> None:
        self.engine.dispose()


def open_catalog(url_or_settings: str | Settings, *, check: bool = True) -> Catalog:
    """Connect to the catalog; with ``check``, refuse a database not at this siteline's revision."""
    url = url_or_settings.database_url if isinstance(url_or_settings, Settings) else url_or_settings
    roots = store_roots(url_or_settings) if isinstance(url_or_settings, Settings) else None
    engine = make_engine(url)
    ping(engine)
    if check:
        from siteline.catalog import migrate  # alembic: only when a catalog is opened

        migrate.check_revision(engine)
    return Catalog(engine=engine, sessions=sessionmaker(engine, expire_on_commit=False), roots=roots)


def store_roots(settings: Settings) -> Roots:
    """The roots the catalog of ``settings`` records store addresses against."""
    return Roots.of(settings.store.url, settings.home)
