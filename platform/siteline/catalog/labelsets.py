"""Catalog reads and writes of label-set versions (one row per version of a scene's semantic
classes). Functions take a session and never commit: the caller owns the transaction."""

from __future__ import annotations

from typing import Any

import sqlalchemy as sa
from sqlalchemy.orm import Session

from siteline.catalog.models import LabelSet
from siteline.errors import LabelSetError


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


def newest_versions(session: Session, scene_ids: list[int]) -> dict[int, int]:
    """Scene id -> its newest label-set version."""
    rows = session.execute(
        sa.select(LabelSet.scene_id, sa.func.max(LabelSet.version))
        .where(LabelSet.scene_id.in_(scene_ids))
        .group_by(LabelSet.scene_id)
    ).all()
    return {int(sid): int(v) for sid, v in rows}


def add_label_set(
    session: Session,
    scene_id: int,
    version: int,
    uri: str,
    parent_version: int,
    source: str,
    source_sha256: str,
    note: str | None,
    class_histogram: dict[str, int],
    changed_points: int,
    details: dict[str, Any],
) -> LabelSet:
    """Record an imported version (its store at ``uri`` already published)."""
    row = LabelSet(
        scene_id=scene_id, version=version, uri=uri, parent_version=parent_version, source=source,
        source_sha256=source_sha256, note=note, class_histogram=class_histogram,
        changed_points=changed_points, details=details,
    )  # fmt: skip
    session.add(row)
    session.flush()
    return row


def label_set_record(row: LabelSet) -> dict[str, Any]:
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
