"""Initial catalog: sites, missions and files, scenes, cameras, label sets, tile nodes, pairs,
views, renders, releases and items, stage runs.

Why: the foundation every pipeline stage records into (DESIGN.md section 8). Downgrade drops all of it.

Revision ID: 0001
Revises:
Create Date: 2026-11-21
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op


revision: str = '0001'
down_revision: str | None = None
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table('release',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('name', sa.String(length=128), nullable=False),
    sa.Column('version', sa.String(length=32), nullable=False),
    sa.Column('status', sa.String(length=16), nullable=False),
    sa.Column('manifest_sha256', sa.String(length=64), nullable=True),
    sa.Column('parameters', sa.JSON(), nullable=False),
    sa.Column('root_uri', sa.Text(), nullable=True),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.Column('published_at', sa.DateTime(timezone=True), nullable=True),
    sa.CheckConstraint("status IN ('draft', 'published')", name=op.f('ck_release_status')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_release')),
    sa.UniqueConstraint('name', 'version', name=op.f('uq_release_name_version'))
    )
    op.create_table('site',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('name', sa.String(length=64), nullable=False),
    sa.Column('crs', sa.Text(), nullable=False),
    sa.Column('origin_x', sa.Double(), nullable=False),
    sa.Column('origin_y', sa.Double(), nullable=False),
    sa.Column('origin_z', sa.Double(), nullable=False),
    sa.Column('fence', sa.JSON(), nullable=True),
    sa.Column('taxonomy', sa.JSON(), nullable=False),
    sa.Column('tile_size_m', sa.Double(), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_site')),
    sa.UniqueConstraint('name', name=op.f('uq_site_name'))
    )
    op.create_table('stage_run',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('stage', sa.String(length=64), nullable=False),
    sa.Column('subject', sa.String(length=256), nullable=False),
    sa.Column('parameters', sa.JSON(), nullable=False),
    sa.Column('status', sa.String(length=16), nullable=False),
    sa.Column('started_at', sa.DateTime(timezone=True), nullable=False),
    sa.Column('finished_at', sa.DateTime(timezone=True), nullable=True),
    sa.Column('error_text', sa.Text(), nullable=True),
    sa.Column('orchestrator_run_id', sa.String(length=64), nullable=True),
    sa.CheckConstraint("status IN ('running', 'completed', 'failed')", name=op.f('ck_stage_run_status')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_stage_run'))
    )
    with op.batch_alter_table('stage_run', schema=None) as batch_op:
        batch_op.create_index('ix_stage_run_subject', ['stage', 'subject'], unique=False)

    op.create_table('mission',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('site_id', sa.Integer(), nullable=False),
    sa.Column('manifest_sha256', sa.String(length=64), nullable=False),
    sa.Column('name', sa.Text(), nullable=False),
    sa.Column('received_at', sa.DateTime(timezone=True), nullable=False),
    sa.Column('status', sa.String(length=16), nullable=False),
    sa.Column('storage', sa.String(length=16), nullable=False),
    sa.Column('root_uri', sa.Text(), nullable=False),
    sa.CheckConstraint("status IN ('received', 'ingested', 'failed')", name=op.f('ck_mission_status')),
    sa.ForeignKeyConstraint(['site_id'], ['site.id'], name=op.f('fk_mission_site_id_site'), ondelete='RESTRICT'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_mission')),
    sa.UniqueConstraint('manifest_sha256', name=op.f('uq_mission_manifest_sha256'))
    )
    with op.batch_alter_table('mission', schema=None) as batch_op:
        batch_op.create_index(batch_op.f('ix_mission_site_id'), ['site_id'], unique=False)

    op.create_table('mission_file',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('mission_id', sa.Integer(), nullable=False),
    sa.Column('path', sa.Text(), nullable=False),
    sa.Column('size_bytes', sa.BigInteger(), nullable=False),
    sa.Column('sha256', sa.String(length=64), nullable=False),
    sa.Column('kind', sa.String(length=16), nullable=False),
    sa.CheckConstraint("kind IN ('las', 'photo', 'colmap', 'trajectory', 'raw', 'other')", name=op.f('ck_mission_file_kind')),
    sa.CheckConstraint('size_bytes >= 0', name=op.f('ck_mission_file_size')),
    sa.ForeignKeyConstraint(['mission_id'], ['mission.id'], name=op.f('fk_mission_file_mission_id_mission'), ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_mission_file')),
    sa.UniqueConstraint('mission_id', 'path', name=op.f('uq_mission_file_mission_id_path'))
    )
    with op.batch_alter_table('mission_file', schema=None) as batch_op:
        batch_op.create_index(batch_op.f('ix_mission_file_mission_id'), ['mission_id'], unique=False)

    op.create_table('scene',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('site_id', sa.Integer(), nullable=False),
    sa.Column('mission_id', sa.Integer(), nullable=False),
    sa.Column('capture_time', sa.DateTime(timezone=True), nullable=False),
    sa.Column('point_count', sa.BigInteger(), nullable=False),
    sa.Column('bounds', sa.JSON(), nullable=False),
    sa.Column('registration', sa.JSON(), nullable=False),
    sa.Column('statistics', sa.JSON(), nullable=False),
    sa.Column('tile_store_uri', sa.Text(), nullable=True),
    sa.Column('status', sa.String(length=16), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.CheckConstraint("status IN ('registered', 'tiled', 'failed')", name=op.f('ck_scene_status')),
    sa.CheckConstraint('point_count >= 0', name=op.f('ck_scene_point_count')),
    sa.ForeignKeyConstraint(['mission_id'], ['mission.id'], name=op.f('fk_scene_mission_id_mission'), ondelete='RESTRICT'),
    sa.ForeignKeyConstraint(['site_id'], ['site.id'], name=op.f('fk_scene_site_id_site'), ondelete='RESTRICT'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_scene')),
    sa.UniqueConstraint('mission_id', name=op.f('uq_scene_mission_id')),
    sa.UniqueConstraint('site_id', 'capture_time', name=op.f('uq_scene_site_id_capture_time'))
    )
    with op.batch_alter_table('scene', schema=None) as batch_op:
        batch_op.create_index(batch_op.f('ix_scene_site_id'), ['site_id'], unique=False)

    op.create_table('camera',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('scene_id', sa.Integer(), nullable=False),
    sa.Column('image_name', sa.Text(), nullable=False),
    sa.Column('width', sa.Integer(), nullable=False),
    sa.Column('height', sa.Integer(), nullable=False),
    sa.Column('fx', sa.Double(), nullable=False),
    sa.Column('fy', sa.Double(), nullable=False),
    sa.Column('cx', sa.Double(), nullable=False),
    sa.Column('cy', sa.Double(), nullable=False),
    sa.Column('rotation', sa.JSON(), nullable=False),
    sa.Column('translation', sa.JSON(), nullable=False),
    sa.Column('source', sa.String(length=16), nullable=False),
    sa.CheckConstraint("source IN ('colmap', 'xmp', 'synthetic')", name=op.f('ck_camera_source')),
    sa.CheckConstraint('width > 0 AND height > 0', name=op.f('ck_camera_size')),
    sa.ForeignKeyConstraint(['scene_id'], ['scene.id'], name=op.f('fk_camera_scene_id_scene'), ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_camera')),
    sa.UniqueConstraint('scene_id', 'image_name', name=op.f('uq_camera_scene_id_image_name'))
    )
    with op.batch_alter_table('camera', schema=None) as batch_op:
        batch_op.create_index(batch_op.f('ix_camera_scene_id'), ['scene_id'], unique=False)

    op.create_table('label_set',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('scene_id', sa.Integer(), nullable=False),
    sa.Column('version', sa.Integer(), nullable=False),
    sa.Column('source', sa.Text(), nullable=False),
    sa.Column('class_histogram', sa.JSON(), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.CheckConstraint('version >= 1', name=op.f('ck_label_set_version')),
    sa.ForeignKeyConstraint(['scene_id'], ['scene.id'], name=op.f('fk_label_set_scene_id_scene'), ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_label_set')),
    sa.UniqueConstraint('scene_id', 'version', name=op.f('uq_label_set_scene_id_version'))
    )
    with op.batch_alter_table('label_set', schema=None) as batch_op:
        batch_op.create_index(batch_op.f('ix_label_set_scene_id'), ['scene_id'], unique=False)

    op.create_table('node',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('scene_id', sa.Integer(), nullable=False),
    sa.Column('key', sa.String(length=64), nullable=False),
    sa.Column('tile', sa.String(length=32), nullable=False),
    sa.Column('level', sa.Integer(), nullable=False),
    sa.Column('min_x', sa.Double(), nullable=False),
    sa.Column('min_y', sa.Double(), nullable=False),
    sa.Column('min_z', sa.Double(), nullable=False),
    sa.Column('max_x', sa.Double(), nullable=False),
    sa.Column('max_y', sa.Double(), nullable=False),
    sa.Column('max_z', sa.Double(), nullable=False),
    sa.Column('point_count', sa.BigInteger(), nullable=False),
    sa.Column('start', sa.BigInteger(), nullable=False),
    sa.Column('spacing_m', sa.Double(), nullable=False),
    sa.CheckConstraint('point_count >= 0 AND start >= 0', name=op.f('ck_node_counts')),
    sa.ForeignKeyConstraint(['scene_id'], ['scene.id'], name=op.f('fk_node_scene_id_scene'), ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_node')),
    sa.UniqueConstraint('scene_id', 'key', name=op.f('uq_node_scene_id_key'))
    )
    with op.batch_alter_table('node', schema=None) as batch_op:
        batch_op.create_index('ix_node_scene_level', ['scene_id', 'level'], unique=False)

    op.create_table('pair',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('site_id', sa.Integer(), nullable=False),
    sa.Column('t1_scene_id', sa.Integer(), nullable=False),
    sa.Column('t2_scene_id', sa.Integer(), nullable=False),
    sa.Column('radius_m', sa.Double(), nullable=True),
    sa.Column('parameters', sa.JSON(), nullable=False),
    sa.Column('status', sa.String(length=16), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.CheckConstraint('t1_scene_id <> t2_scene_id', name=op.f('ck_pair_distinct_scenes')),
    sa.ForeignKeyConstraint(['site_id'], ['site.id'], name=op.f('fk_pair_site_id_site'), ondelete='RESTRICT'),
    sa.ForeignKeyConstraint(['t1_scene_id'], ['scene.id'], name=op.f('fk_pair_t1_scene_id_scene'), ondelete='RESTRICT'),
    sa.ForeignKeyConstraint(['t2_scene_id'], ['scene.id'], name=op.f('fk_pair_t2_scene_id_scene'), ondelete='RESTRICT'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_pair')),
    sa.UniqueConstraint('t1_scene_id', 't2_scene_id', name=op.f('uq_pair_t1_scene_id_t2_scene_id'))
    )
    with op.batch_alter_table('pair', schema=None) as batch_op:
        batch_op.create_index(batch_op.f('ix_pair_site_id'), ['site_id'], unique=False)

    op.create_table('view',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('pair_id', sa.Integer(), nullable=False),
    sa.Column('param_digest', sa.String(length=16), nullable=False),
    sa.Column('index', sa.Integer(), nullable=False),
    sa.Column('strategy', sa.String(length=64), nullable=False),
    sa.Column('parent_camera_id', sa.Integer(), nullable=True),
    sa.Column('parameters', sa.JSON(), nullable=False),
    sa.Column('camera', sa.JSON(), nullable=False),
    sa.ForeignKeyConstraint(['pair_id'], ['pair.id'], name=op.f('fk_view_pair_id_pair'), ondelete='CASCADE'),
    sa.ForeignKeyConstraint(['parent_camera_id'], ['camera.id'], name=op.f('fk_view_parent_camera_id_camera'), ondelete='SET NULL'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_view')),
    sa.UniqueConstraint('pair_id', 'param_digest', 'index', name=op.f('uq_view_pair_id_param_digest_index'))
    )
    op.create_table('release_item',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('release_id', sa.Integer(), nullable=False),
    sa.Column('item_id', sa.String(length=128), nullable=False),
    sa.Column('pair_id', sa.Integer(), nullable=False),
    sa.Column('view_id', sa.Integer(), nullable=True),
    sa.Column('split', sa.String(length=8), nullable=False),
    sa.Column('coverage', sa.Double(), nullable=False),
    sa.Column('change_ratio', sa.Double(), nullable=False),
    sa.Column('files', sa.JSON(), nullable=False),
    sa.CheckConstraint("split IN ('train', 'val', 'test')", name=op.f('ck_release_item_split')),
    sa.ForeignKeyConstraint(['pair_id'], ['pair.id'], name=op.f('fk_release_item_pair_id_pair'), ondelete='RESTRICT'),
    sa.ForeignKeyConstraint(['release_id'], ['release.id'], name=op.f('fk_release_item_release_id_release'), ondelete='CASCADE'),
    sa.ForeignKeyConstraint(['view_id'], ['view.id'], name=op.f('fk_release_item_view_id_view'), ondelete='SET NULL'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_release_item')),
    sa.UniqueConstraint('release_id', 'item_id', name=op.f('uq_release_item_release_id_item_id'))
    )
    with op.batch_alter_table('release_item', schema=None) as batch_op:
        batch_op.create_index(batch_op.f('ix_release_item_release_id'), ['release_id'], unique=False)

    op.create_table('render',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('view_id', sa.Integer(), nullable=False),
    sa.Column('scene_id', sa.Integer(), nullable=False),
    sa.Column('scale', sa.Double(), nullable=False),
    sa.Column('point_size_px', sa.Integer(), nullable=False),
    sa.Column('coverage', sa.Double(), nullable=False),
    sa.Column('change_ratio', sa.Double(), nullable=True),
    sa.Column('paths', sa.JSON(), nullable=False),
    sa.CheckConstraint('coverage >= 0 AND coverage <= 1', name=op.f('ck_render_coverage')),
    sa.ForeignKeyConstraint(['scene_id'], ['scene.id'], name=op.f('fk_render_scene_id_scene'), ondelete='CASCADE'),
    sa.ForeignKeyConstraint(['view_id'], ['view.id'], name=op.f('fk_render_view_id_view'), ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_render')),
    sa.UniqueConstraint('view_id', 'scene_id', 'scale', 'point_size_px', name=op.f('uq_render_view_id_scene_id_scale_point_size_px'))
    )


def downgrade() -> None:
    op.drop_table('render')
    with op.batch_alter_table('release_item', schema=None) as batch_op:
        batch_op.drop_index(batch_op.f('ix_release_item_release_id'))

    op.drop_table('release_item')
    op.drop_table('view')
    with op.batch_alter_table('pair', schema=None) as batch_op:
        batch_op.drop_index(batch_op.f('ix_pair_site_id'))

    op.drop_table('pair')
    with op.batch_alter_table('node', schema=None) as batch_op:
        batch_op.drop_index('ix_node_scene_level')

    op.drop_table('node')
    with op.batch_alter_table('label_set', schema=None) as batch_op:
        batch_op.drop_index(batch_op.f('ix_label_set_scene_id'))

    op.drop_table('label_set')
    with op.batch_alter_table('camera', schema=None) as batch_op:
        batch_op.drop_index(batch_op.f('ix_camera_scene_id'))

    op.drop_table('camera')
    with op.batch_alter_table('scene', schema=None) as batch_op:
        batch_op.drop_index(batch_op.f('ix_scene_site_id'))

    op.drop_table('scene')
    with op.batch_alter_table('mission_file', schema=None) as batch_op:
        batch_op.drop_index(batch_op.f('ix_mission_file_mission_id'))

    op.drop_table('mission_file')
    with op.batch_alter_table('mission', schema=None) as batch_op:
        batch_op.drop_index(batch_op.f('ix_mission_site_id'))

    op.drop_table('mission')
    with op.batch_alter_table('stage_run', schema=None) as batch_op:
        batch_op.drop_index('ix_stage_run_subject')

    op.drop_table('stage_run')
    op.drop_table('site')
    op.drop_table('release')
