"""Label-set versions: where a corrected label set is stored and what it changed.

Why: corrected semantic labels come back as new label-set versions (DESIGN.md section 1); each row
now says where its classes live (``uri``; NULL: the tile store's own classes, version 1), which file
and note it came from, the version it corrected and how many points changed. Downgrade drops these
columns and the rows of versions above 1 (their stores stay in the store; nothing reads them).

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-23
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0002"
down_revision: str | None = "0001"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("label_set", schema=None) as batch_op:
        batch_op.add_column(sa.Column("uri", sa.Text(), nullable=True))
        batch_op.add_column(sa.Column("parent_version", sa.Integer(), nullable=True))
        batch_op.add_column(sa.Column("source_sha256", sa.String(length=64), nullable=True))
        batch_op.add_column(sa.Column("note", sa.Text(), nullable=True))
        batch_op.add_column(sa.Column("changed_points", sa.BigInteger(), nullable=True))
        batch_op.add_column(sa.Column("details", sa.JSON(), nullable=True))


def downgrade() -> None:
    op.execute("DELETE FROM label_set WHERE version > 1")
    with op.batch_alter_table("label_set", schema=None) as batch_op:
        batch_op.drop_column("details")
        batch_op.drop_column("changed_points")
        batch_op.drop_column("note")
        batch_op.drop_column("source_sha256")
        batch_op.drop_column("parent_version")
        batch_op.drop_column("uri")
