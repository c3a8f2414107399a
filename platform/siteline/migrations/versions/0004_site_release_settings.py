"""Release settings belong to the site: a preset and explicit knobs stored with it.

Why: the service built every release with bare parameter defaults (scale 0.125, 1 px points: the
paper's setting for 5645 px photos), which on 660 px cameras published 83 x 62 px renders. A site now
carries its release settings (siteline.release.knobs; empty means auto scale and point size from its
cameras); the CLI, the demo and the flows all build with them. Downgrade drops the column (releases
already built keep their parameters in their lineage).

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-23
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0004"
down_revision: str | None = "0003"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


# Plain ALTER TABLE (SQLite 3.35+ adds and drops columns in place): a batch copy of "site" would have
# to drop a table every other table refers to.
def upgrade() -> None:
    op.add_column("site", sa.Column("release_settings", sa.JSON(), nullable=False, server_default="{}"))


def downgrade() -> None:
    op.drop_column("site", "release_settings")
