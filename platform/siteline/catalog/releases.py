"""Catalog reads and writes of releases and their items. Functions take a session and never commit:
the caller owns the transaction."""

from __future__ import annotations

from datetime import datetime

import sqlalchemy as sa
from sqlalchemy.orm import Session

from siteline.catalog.models import Pair, Release, ReleaseItem, Scene
from siteline.errors import NotFoundError


def find_release(session: Session, name: str, version: str) -> Release | None:
    """The release row ``name`` ``version``, or None."""
    return session.execute(
        sa.select(Release).where(Release.name == name, Release.version == version)
    ).scalar_one_or_none()


def get_release(session: Session, name: str, version: str) -> Release:
    """The release row ``name`` ``version``; :class:`NotFoundError` when there is none."""
    rel = find_release(session, name, version)
    if rel is None:
        raise NotFoundError(f"no release {name} {version}; see `siteline release list`.")
    return rel


def list_releases(session: Session, name: str | None = None) -> list[Release]:
    q = sa.select(Release).order_by(Release.name, Release.created_at)
    if name:
        q = q.where(Release.name == name)
    return list(session.execute(q).scalars())


def release_item_counts(session: Session, release_id: int) -> dict[str, int]:
    """Items of a release per split."""
    rows = session.execute(
        sa.select(ReleaseItem.split, sa.func.count())
        .where(ReleaseItem.release_id == release_id)
        .group_by(ReleaseItem.split)
    ).all()
    return {split: int(n) for split, n in rows}


def clear_release_items(session: Session, release_id: int) -> None:
    """Remove a (draft) release's item rows before they are written again."""
    session.execute(sa.delete(ReleaseItem).where(ReleaseItem.release_id == release_id))


def query_items(
    session: Session,
    name: str,
    version: str,
    min_change_ratio: float | None = None,
    split: str | None = None,
    since: datetime | None = None,
    until: datetime | None = None,
) -> list[dict]:
    """Items of a release with a change ratio above a threshold, of a split, or whose pair's scenes
    were captured in [since, until]."""
    rel = get_release(session, name, version)
    t1 = sa.orm.aliased(Scene)
    t2 = sa.orm.aliased(Scene)
    q = (
        sa.select(ReleaseItem, t1.capture_time, t2.capture_time)
        .join(Pair, Pair.id == ReleaseItem.pair_id)
        .join(t1, t1.id == Pair.t1_scene_id)
        .join(t2, t2.id == Pair.t2_scene_id)
        .where(ReleaseItem.release_id == rel.id)
        .order_by(ReleaseItem.item_id)
    )
    if min_change_ratio is not None:
        q = q.where(ReleaseItem.change_ratio > min_change_ratio)
    if split is not None:
        q = q.where(ReleaseItem.split == split)
    if since is not None:
        q = q.where(t1.capture_time >= since)
    if until is not None:
        q = q.where(t2.capture_time <= until)
    return [
        {
            "id": it.item_id,
            "split": it.split,
            "pair": it.pair_id,
            "change_ratio": it.change_ratio,
            "coverage": it.coverage,
            "t1_time": a,
            "t2_time": b,
            "files": it.files,
        }
        for it, a, b in session.execute(q).all()
    ]
