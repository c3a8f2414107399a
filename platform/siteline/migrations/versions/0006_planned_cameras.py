"""Cameras may be planned from the point cloud ('planned'), not only taken from photos.

Why: most real clouds reach users as LAS/LAZ alone (a surveyor's export, an airborne survey, another
vendor's scan); siteline then plans the capture cameras from the scene's extent and ground
(siteline.register.planned) and records them like photo cameras, with their source. Upgrade widens
the camera table's source check; downgrade removes planned cameras (their scenes then have none, as
before) and narrows it again.

Revision ID: 0006
Revises: 0005
Create Date: 2026-11-25
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0006"
down_revision: str | None = "0005"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

OLD = "source IN ('colmap', 'xmp', 'synthetic')"
NEW = "source IN ('colmap', 'xmp', 'synthetic', 'planned')"


def _check(sql: str) -> None:
    with op.batch_alter_table("camera", schema=None) as batch_op:
        batch_op.drop_constraint(op.f("ck_camera_source"), type_="check")
        batch_op.create_check_constraint(op.f("ck_camera_source"), sql)


def upgrade() -> None:
    _check(NEW)


def downgrade() -> None:
    op.get_bind().execute(sa.text("DELETE FROM camera WHERE source = 'planned'"))
    _check(OLD)
