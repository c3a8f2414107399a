"""Octree nodes: a node is one level of one octree cube of a tile.

Why: views read fine levels only where they need them (DESIGN.md section 7), so a node must be
smaller than a whole tile level. The cube is recorded per node; stores written before keep NULL cubes
(whole-tile levels), which readers still use as they are. Downgrade drops the columns (the node rows
of octree stores stay valid ranges; re-tile to get whole-level nodes back).

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-23
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0003"
down_revision: str | None = "0002"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("node", schema=None) as batch_op:
        batch_op.add_column(sa.Column("cell_x", sa.Integer(), nullable=True))
        batch_op.add_column(sa.Column("cell_y", sa.Integer(), nullable=True))
        batch_op.add_column(sa.Column("cell_z", sa.Integer(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("node", schema=None) as batch_op:
        batch_op.drop_column("cell_z")
        batch_op.drop_column("cell_y")
        batch_op.drop_column("cell_x")
