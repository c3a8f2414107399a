"""Sites that can be corrected: a site has a version (its taxonomy and fence), and a mission may be
ingested into several sites.

Why: a user who got a site's taxonomy or fence wrong could only start again in a new home; `site
update --taxonomy/--fence` now records the site's next version (the earlier ones kept in
``site.history``) and re-tiles its scenes under it (each tiling records the site version it used).
The same survey often covers two sites (neighbouring plots, a site and its trial), so a mission is
unique per site, not across the catalog. Downgrade keeps each manifest's first mission only if no
other exists (it refuses otherwise) and drops the version columns.

Revision ID: 0007
Revises: 0006
Create Date: 2026-11-25
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0007"
down_revision: str | None = "0006"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("site", schema=None) as batch_op:
        batch_op.add_column(sa.Column("version", sa.Integer(), nullable=False, server_default="1"))
        batch_op.add_column(sa.Column("history", sa.JSON(), nullable=False, server_default="[]"))
    with op.batch_alter_table("mission", schema=None) as batch_op:
        batch_op.drop_constraint(op.f("uq_mission_manifest_sha256"), type_="unique")
        batch_op.create_unique_constraint(op.f("uq_mission_site_id_manifest_sha256"), ["site_id", "manifest_sha256"])


def downgrade() -> None:
    shared = op.get_bind().execute(
        sa.text("SELECT manifest_sha256 FROM mission GROUP BY manifest_sha256 HAVING COUNT(*) > 1")
    ).first()
    if shared is not None:
        raise RuntimeError(
            f"mission manifest {shared[0][:12]} is ingested into several sites: delete all but one "
            "(`siteline scene delete`) before downgrading."
        )
    with op.batch_alter_table("mission", schema=None) as batch_op:
        batch_op.drop_constraint(op.f("uq_mission_site_id_manifest_sha256"), type_="unique")
        batch_op.create_unique_constraint(op.f("uq_mission_manifest_sha256"), ["manifest_sha256"])
    with op.batch_alter_table("site", schema=None) as batch_op:
        batch_op.drop_column("history")
        batch_op.drop_column("version")
