"""Store addresses recorded relative to the store root or SITELINE_HOME.

Why: the catalog recorded absolute paths, so a home copied or restored elsewhere (``cp -a home
home2``) read and wrote the first home's stores, and ``release verify`` on the copy checked the
original. Addresses are now recorded as ``store:<path>`` or ``home:<path>``
(siteline.catalog.addresses). This migration rewrites the addresses already recorded under the roots
of the settings that run it (``siteline db upgrade``); run without them (a bare URL) it leaves them
absolute, which still read as before. Downgrade writes them absolute again under the
roots of the settings that run it (and refuses without them when relative ones are recorded).

Revision ID: 0008
Revises: 0007
Create Date: 2026-11-26
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import sqlalchemy as sa
from alembic import op

from siteline.catalog.addresses import current_roots, from_record, to_record

revision: str = "0008"
down_revision: str | None = "0007"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

_TEXT = (("mission", "root_uri"), ("scene", "tile_store_uri"), ("label_set", "uri"), ("release", "root_uri"))


def _rewrite(convert: Callable[[str], str]) -> None:
    bind = op.get_bind()
    for name, column in _TEXT:
        table = sa.table(name, sa.column("id", sa.Integer), sa.column(column, sa.Text))
        for row_id, value in bind.execute(sa.select(table.c.id, table.c[column])).all():
            if value is not None and convert(value) != value:
                bind.execute(table.update().where(table.c.id == row_id).values({column: convert(value)}))
    _rewrite_json(bind, "scene", "statistics", convert, lambda doc: [doc.get("tiles") or {}], "uri")
    _rewrite_json(bind, "render", "paths", convert, lambda doc: [doc], None)
    _rewrite_json(
        bind, "pair", "parameters", convert,
        lambda doc: [v["labels"] for v in doc.values() if isinstance(v, dict) and isinstance(v.get("labels"), dict)],
        "uri",
    )  # fmt: skip


def _rewrite_json(
    bind: sa.Connection, name: str, column: str, convert: Callable[[str], str],
    holders: Callable[[dict[str, Any]], list[dict[str, Any]]], key: str | None,
) -> None:  # fmt: skip
    table = sa.table(name, sa.column("id", sa.Integer), sa.column(column, sa.JSON))
    for row_id, doc in bind.execute(sa.select(table.c.id, table.c[column])).all():
        if not isinstance(doc, dict):
            continue
        changed = False
        for holder in holders(doc):
            for k in [key] if key is not None else list(holder):
                value = holder.get(k)
                if isinstance(value, str) and convert(value) != value:
                    holder[k], changed = convert(value), True
        if changed:
            bind.execute(table.update().where(table.c.id == row_id).values({column: doc}))


def upgrade() -> None:
    if current_roots() is not None:
        _rewrite(to_record)


def downgrade() -> None:
    _rewrite(from_record)  # refuses, naming the settings to use, when relative ones meet no roots
