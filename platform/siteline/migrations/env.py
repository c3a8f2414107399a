"""Alembic environment for the siteline catalog.

siteline drives Alembic from Python (``siteline db ...``) and hands over its engine in
``config.attributes["engine"]``; the plain ``alembic`` command works too, reading the URL from
``SITELINE_DATABASE_URL`` (or the SQLite catalog under ``SITELINE_HOME``).
"""

from __future__ import annotations

from alembic import context

from siteline.catalog import Base  # importing the catalog registers every table
from siteline.catalog.addresses import current_roots, rooted

config = context.config
target_metadata = Base.metadata


def _engine():
    engine = config.attributes.get("engine")
    if engine is not None:
        return engine
    from siteline.catalog.engine import make_engine
    from siteline.config import load_settings

    return make_engine(load_settings().database_url)


def run_migrations_offline() -> None:
    context.configure(
        url=config.get_main_option("sqlalchemy.url"),
        target_metadata=target_metadata,
        literal_binds=True,
        render_as_batch=True,
    )
    with context.begin_transaction():
        context.run_migrations()


def run_migrations_online() -> None:
    engine = _engine()
    with engine.connect() as connection:
        sqlite = connection.dialect.name == "sqlite"
        if sqlite:
            # a batch rebuild drops and recreates a table: with foreign keys enforced, dropping one that
            # other rows reference (mission, by scene) fails; the rebuilt table keeps the same rows.
            # The pragma is a no-op inside a transaction, so it is set before one begins.
            connection.commit()
            connection.exec_driver_sql("PRAGMA foreign_keys=OFF")
        context.configure(
            connection=connection,
            target_metadata=target_metadata,
            # SQLite cannot ALTER most things: batch mode rebuilds tables for it.
            render_as_batch=connection.dialect.name == "sqlite",
            compare_type=True,
        )
        with context.begin_transaction():
            context.run_migrations()
        connection.commit()
        if sqlite:
            problems = connection.exec_driver_sql("PRAGMA foreign_key_check").all()
            connection.exec_driver_sql("PRAGMA foreign_keys=ON")
            if problems:
                raise RuntimeError(f"the migration left rows whose references are gone: {problems[:5]}")


if context.is_offline_mode():
    run_migrations_offline()
elif config.attributes.get("engine") is None and current_roots() is None:
    # the plain `alembic` command: store addresses are recorded against the configured home
    from siteline.catalog import store_roots
    from siteline.config import load_settings

    with rooted(store_roots(load_settings())):
        run_migrations_online()
else:
    run_migrations_online()
