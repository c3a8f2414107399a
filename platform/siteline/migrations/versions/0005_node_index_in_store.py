"""The node index lives in the tile store, not in the catalog.

Why: at paper density a scene holds 200-800M points; one catalog row per node (and the same list
again as JSON in the store's attributes) made tiling and every reader's start-up grow with the node
count. A tile store now keeps its node index as one set of compact arrays (``nodes/`` in the Zarr
group, siteline.tiles.index), nodes hold thousands of points, and the catalog records the count per
scene. Upgrade writes each tiled scene's node count into its tiling statistics, then drops the table
(stores written before keep their node list in their attributes, which readers still use).
Downgrade recreates the empty table: re-tile scenes (`siteline scene tile --retile`) under the
older version to index them again.

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-23
"""

from __future__ import annotations

import json
from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0005"
down_revision: str | None = "0004"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    bind = op.get_bind()
    counts = dict(bind.execute(sa.text("SELECT scene_id, count(*) FROM node GROUP BY scene_id")).all())
    scene = sa.table("scene", sa.column("id", sa.Integer), sa.column("statistics", sa.JSON))
    for sid, stats in bind.execute(sa.select(scene.c.id, scene.c.statistics)).all():
        doc = json.loads(stats) if isinstance(stats, str) else dict(stats or {})
        tiles = doc.get("tiles")
        if isinstance(tiles, dict) and sid in counts:
            doc["tiles"] = {**tiles, "nodes": int(counts[sid])}
            bind.execute(scene.update().where(scene.c.id == sid).values(statistics=doc))
    op.drop_index("ix_node_scene_level", table_name="node")
    op.drop_table("node")


def downgrade() -> None:
    op.create_table(
        "node",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("scene_id", sa.Integer(), nullable=False),
        sa.Column("key", sa.String(length=64), nullable=False),
        sa.Column("tile", sa.String(length=32), nullable=False),
        sa.Column("level", sa.Integer(), nullable=False),
        sa.Column("min_x", sa.Double(), nullable=False),
        sa.Column("min_y", sa.Double(), nullable=False),
        sa.Column("min_z", sa.Double(), nullable=False),
        sa.Column("max_x", sa.Double(), nullable=False),
        sa.Column("max_y", sa.Double(), nullable=False),
        sa.Column("max_z", sa.Double(), nullable=False),
        sa.Column("point_count", sa.BigInteger(), nullable=False),
        sa.Column("start", sa.BigInteger(), nullable=False),
        sa.Column("spacing_m", sa.Double(), nullable=False),
        sa.Column("cell_x", sa.Integer(), nullable=True),
        sa.Column("cell_y", sa.Integer(), nullable=True),
        sa.Column("cell_z", sa.Integer(), nullable=True),
        sa.CheckConstraint("point_count >= 0 AND start >= 0", name=op.f("ck_node_counts")),
        sa.ForeignKeyConstraint(["scene_id"], ["scene.id"], name=op.f("fk_node_scene_id_scene"), ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_node")),
        sa.UniqueConstraint("scene_id", "key", name=op.f("uq_node_scene_id_key")),
    )
    op.create_index("ix_node_scene_level", "node", ["scene_id", "level"], unique=False)
