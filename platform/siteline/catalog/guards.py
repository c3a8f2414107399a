"""Invariants the database alone cannot express, enforced on every flush of every session."""

from __future__ import annotations

from typing import Any

import sqlalchemy as sa
from sqlalchemy import event
from sqlalchemy.orm import Session

from siteline.catalog.models import Release, ReleaseItem
from siteline.errors import ImmutableError


def _was_published(release: Release) -> bool:
    """Whether the row was published in the database before this flush."""
    history = sa.inspect(release).attrs.status.history
    if history.deleted:
        return history.deleted[0] == "published"
    if history.unchanged:
        return history.unchanged[0] == "published"
    return False


def _release_published(session: Session, release_id: int | None) -> bool:
    if release_id is None:
        return False
    status = session.execute(sa.select(Release.status).where(Release.id == release_id)).scalar_one_or_none()
    return status == "published"


@event.listens_for(Session, "before_flush")
def _refuse_changes_to_published_releases(session: Session, flush_context: Any, instances: Any) -> None:
    for obj in list(session.dirty) + list(session.deleted):
        if isinstance(obj, Release) and _was_published(obj):
            if obj in session.deleted or session.is_modified(obj, include_collections=False):
                raise ImmutableError(
                    f"release {obj.name} {obj.version} is published and cannot be modified or deleted: "
                    "build a new version instead."
                )
    for obj in list(session.new) + list(session.dirty) + list(session.deleted):
        if isinstance(obj, ReleaseItem):
            if obj in session.dirty and not session.is_modified(obj, include_collections=False):
                continue
            with session.no_autoflush:
                published = _release_published(session, obj.release_id)
            if published:
                raise ImmutableError(
                    f"release item {obj.item_id} belongs to a published release, which cannot be modified: "
                    "build a new version instead."
                )
