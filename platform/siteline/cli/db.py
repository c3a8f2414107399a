"""``siteline init`` and ``siteline db ...``: create and migrate the catalog."""

from __future__ import annotations

import sqlalchemy as sa
import typer

from siteline.catalog import store_roots
from siteline.catalog.engine import make_engine, ping
from siteline.cli.common import JsonOption, console, emit, print_record, settings

app = typer.Typer(help="Migrate the catalog database (Alembic).", no_args_is_help=True)


def _engine() -> sa.Engine:
    engine = make_engine(settings().database_url)
    ping(engine)
    return engine


def init() -> None:
    """Create SITELINE_HOME and its stores, and migrate the catalog to the newest revision."""
    from siteline.catalog import migrate  # alembic: only for commands that migrate

    cfg = settings()
    cfg.home.mkdir(parents=True, exist_ok=True)
    cfg.store.ensure()
    engine = _engine()
    try:
        migrate.upgrade(engine, "head", store_roots(cfg))
        rev = migrate.current_revision(engine)
    finally:
        engine.dispose()
    console.print(
        f"siteline home {cfg.home}, catalog {engine.url.render_as_string(hide_password=True)} at revision {rev}, "
        f"stores at {cfg.store.url}"
    )


@app.command("upgrade")
def upgrade(revision: str = typer.Argument("head", help="Target revision.")) -> None:
    """Migrate the catalog up to REVISION (default: the newest)."""
    from siteline.catalog import migrate  # alembic: only for commands that migrate

    engine = _engine()
    try:
        migrate.upgrade(engine, revision, store_roots(settings()))
        console.print(f"catalog at revision {migrate.current_revision(engine)}")
    finally:
        engine.dispose()


@app.command("downgrade")
def downgrade(
    revision: str = typer.Argument(..., help="Target revision, or 'base' to drop every table."),
) -> None:
    """Migrate the catalog down to REVISION."""
    from siteline.catalog import migrate  # alembic: only for commands that migrate

    engine = _engine()
    try:
        migrate.downgrade(engine, revision, store_roots(settings()))
        console.print(f"catalog at revision {migrate.current_revision(engine)}")
    finally:
        engine.dispose()


@app.command("current")
def current(as_json: bool = JsonOption) -> None:
    """Show the catalog's revision and this siteline's newest."""
    from siteline.catalog import migrate  # alembic: only for commands that migrate

    engine = _engine()
    try:
        record: dict[str, object] = {
            "url": engine.url.render_as_string(hide_password=True),
            "current": migrate.current_revision(engine),
            "head": migrate.head_revision(),
        }
    finally:
        engine.dispose()
    record["up_to_date"] = record["current"] == record["head"]
    emit(as_json, record, lambda: print_record("catalog", record))
