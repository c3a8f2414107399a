"""Alembic migrations of the catalog, driven from Python (``siteline db ...``)."""

from __future__ import annotations

from pathlib import Path

import sqlalchemy as sa
from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory

from siteline.catalog.addresses import Roots, rooted
from siteline.errors import CatalogError, RevisionMismatchError

# shipped inside the package (the repository's top-level migrations/ links here)
MIGRATIONS_DIR = Path(__file__).resolve().parents[1] / "migrations"


def alembic_config(engine: sa.Engine) -> Config:
    """An Alembic config whose migrations run on ``engine``."""
    if not (MIGRATIONS_DIR / "env.py").is_file():
        raise CatalogError(
            f"migrations folder {MIGRATIONS_DIR} is missing: the siteline installation is incomplete (reinstall it)."
        )
    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS_DIR))
    cfg.set_main_option("sqlalchemy.url", engine.url.render_as_string(hide_password=False).replace("%", "%%"))
    cfg.attributes["engine"] = engine
    return cfg


def head_revision() -> str:
    """The newest revision this siteline knows."""
    script = ScriptDirectory.from_config(_script_config())
    heads = script.get_heads()
    if len(heads) != 1:
        raise CatalogError(f"migrations have {len(heads)} heads {heads}; merge them.")
    return heads[0]


def _script_config() -> Config:
    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS_DIR))
    return cfg


def known_revisions() -> set[str]:
    script = ScriptDirectory.from_config(_script_config())
    return {rev.revision for rev in script.walk_revisions()}


def current_revision(engine: sa.Engine) -> str | None:
    """The revision the database is at, or None for a database never migrated."""
    with engine.connect() as conn:
        return MigrationContext.configure(conn).get_current_revision()


def upgrade(engine: sa.Engine, revision: str = "head", roots: Roots | None = None) -> None:
    """Migrate up to ``revision``; ``roots`` (the home's and store's) let a migration record store
    addresses relative to them (without, addresses written before stay as they were)."""
    with rooted(roots):
        command.upgrade(alembic_config(engine), revision)


def downgrade(engine: sa.Engine, revision: str = "base", roots: Roots | None = None) -> None:
    with rooted(roots):
        command.downgrade(alembic_config(engine), revision)


def check_revision(engine: sa.Engine) -> None:
    """Refuse a database at another revision than this siteline's head, saying which command fixes it."""
    where = engine.url.render_as_string(hide_password=True)
    current = current_revision(engine)
    head = head_revision()
    if current == head:
        return
    if current is None:
        raise RevisionMismatchError(
            f"the catalog at {where} is not initialised: run `siteline init` (or `siteline db upgrade`)."
        )
    if current not in known_revisions():
        raise RevisionMismatchError(
            f"the catalog at {where} is at revision {current}, which this siteline does not know "
            f"(its newest is {head}): it was migrated by another siteline version; upgrade siteline, "
            "or run that version's `siteline db downgrade` to a shared revision."
        )
    raise RevisionMismatchError(
        f"the catalog at {where} is at revision {current}, but this siteline needs {head}: run `siteline db upgrade`."
    )
