"""A release item records how much of its change shows in its images (issue 60).

Why: a close-up of a slab that gained a floor is all changed and shows nothing; users filter such
items out (``siteline release query --min-change-visible``). Items of releases built before have
none (NULL). Downgrade drops the column (the manifests keep their items' figures).

Revision ID: 0009
Revises: 0008
Create Date: 2026-11-28
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0009"
down_revision: str | None = "0008"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def _has_column() -> bool:
    return "change_visible" in {c["name"] for c in sa.inspect(op.get_bind()).get_columns("release_item")}


# Both directions check the column first: SQLite commits an ALTER TABLE of its own, so a downgrade
# refused further down (0007 with a mission in two sites) leaves this step done but not stamped, and
# the next try must not fail on it.
def upgrade() -> None:
    if not _has_column():
        op.add_column("release_item", sa.Column("change_visible", sa.Double(), nullable=True))


def downgrade() -> None:
    if _has_column():
        op.drop_column("release_item", "change_visible")
