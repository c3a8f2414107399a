"""Catalog reads and writes of label-set versions (one row per version of a scene's semantic
classes). Functions take a session and never commit: the caller owns the transaction."""

from __future__ import annotations

import sqlalchemy as sa
from sqlalchemy.orm import Session

from siteline.catalog.models import LabelSet
from siteline.catalog.scenes import tile_source
from siteline.catalog.stages import add_completed
from siteline.errors import LabelSetError
from siteline.records.labelsets import LabelSetImport, LabelSetRef
from siteline.records.runs import StageRun
from siteline.records.tiling import TileSource


def label_sets(session: Session, scene_id: int) -> list[LabelSet]:
    """The scene's label-set versions, oldest first."""
    return list(
        session.execute(
            sa.select(LabelSet).where(LabelSet.scene_id == scene_id).order_by(LabelSet.version)
        ).scalars()
    )


def label_set(session: Session, scene_id: int, version: int | None = None) -> LabelSet:
    """Version ``version`` of the scene's label set (None: the newest); LabelSetError names the
    versions there are when it does not exist."""
    rows = label_sets(session, scene_id)
    if not rows:
        raise LabelSetError(f"scene {scene_id} has no label set; is it ingested?")
    if version is None:
        return rows[-1]
    for row in rows:
        if row.version == version:
            return row
    have = ", ".join(str(r.version) for r in rows)
    raise LabelSetError(f"scene {scene_id} has no label-set version {version} (it has {have}).")


def label_set_ref(session: Session, scene_id: int, version: int | None = None) -> LabelSetRef:
    """Version ``version`` of the scene's label set (None: the newest) as a reader needs it."""
    row = label_set(session, scene_id, version)
    return LabelSetRef(scene_id, row.version, row.uri, row.source, row.source_sha256)


def labelled_source(
    session: Session, scene_id: int, version: int | None = None
) -> tuple[TileSource, LabelSetRef]:
    """The scene's tiles and its label-set ``version`` (None: the newest): what
    ``siteline.labelsets.store.open_labelled`` opens."""
    return tile_source(session, scene_id), label_set_ref(session, scene_id, version)


def newest_versions(session: Session, scene_ids: list[int]) -> dict[int, int]:
    """Scene id -> its newest label-set version."""
    rows = session.execute(
        sa.select(LabelSet.scene_id, sa.func.max(LabelSet.version))
        .where(LabelSet.scene_id.in_(scene_ids))
        .group_by(LabelSet.scene_id)
    ).all()
    return {int(sid): int(v) for sid, v in rows}


def record_label_set(session: Session, result: LabelSetImport, run: StageRun) -> LabelSet:
    """Record an imported version whose store is already published, and the stage run. The unique
    (scene, version) constraint refuses a version another import recorded meanwhile."""
    row = LabelSet(
        scene_id=result.scene_id, version=result.version, uri=result.uri, parent_version=result.parent_version,
        source=f"import {result.file}", source_sha256=result.source_sha256, note=result.note,
        class_histogram=result.class_histogram, changed_points=result.changed, details=result.details(),
    )  # fmt: skip
    session.add(row)
    session.flush()
    add_completed(session, run)
    return row


def label_set_record(row: LabelSet) -> dict[str, object]:
    """A label-set row as plain values (for the CLI and the lineage)."""
    return {
        "scene": row.scene_id,
        "version": row.version,
        "parent_version": row.parent_version,
        "source": row.source,
        "source_sha256": row.source_sha256,
        "note": row.note,
        "created_at": row.created_at,
        "uri": row.uri,
        "class_histogram": row.class_histogram,
        "changed_points": row.changed_points,
        "details": row.details or {},
    }
