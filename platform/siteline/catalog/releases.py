"""Catalog reads and writes of releases and their items. Functions take a session and never commit:
the caller owns the transaction."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

import sqlalchemy as sa
from sqlalchemy.orm import Session

from siteline.catalog.models import Pair, Release, ReleaseItem, Scene
from siteline.catalog.pairs import get_pair, pair_view_ids
from siteline.catalog.sites import lock_site
from siteline.catalog.stages import add_completed
from siteline.errors import NotFoundError, ReleaseError
from siteline.records.release import DraftRelease
from siteline.records.runs import StageRun


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


def earlier_item_splits(session: Session, name: str, version: str) -> dict[tuple[int, int], str]:
    """(pair id, view index) -> split of every item of the latest version of ``name`` before
    ``version`` (empty for a first version), and ``left_out`` for the views it left out of every
    split: what a new version keeps (siteline.release.splits)."""

    def semver(v: str) -> tuple[int, ...]:
        return tuple(int(x) for x in v.split("."))

    rows = [r for r in list_releases(session, name) if semver(r.version) < semver(version)]
    if not rows:
        return {}
    latest = max(rows, key=lambda r: semver(r.version))
    items = session.execute(
        sa.select(ReleaseItem.pair_id, ReleaseItem.item_id, ReleaseItem.split).where(
            ReleaseItem.release_id == latest.id
        )
    ).all()
    out = {(pid, int(item.rsplit("_v", 1)[1])): split for pid, item, split in items}
    for pid, view in (latest.parameters or {}).get("left_out") or []:
        out.setdefault((int(pid), int(view)), "left_out")
    return out


def release_item_files(session: Session, release_id: int) -> list[str]:
    """Every image path (relative to the release root) the catalog recorded for a release's items."""
    rows = session.scalars(sa.select(ReleaseItem.files).where(ReleaseItem.release_id == release_id))
    return sorted(path for files in rows for path in files.values())


def release_record(session: Session, rel: Release) -> dict[str, object]:
    items = release_item_counts(session, rel.id)
    return {
        "name": rel.name,
        "version": rel.version,
        "status": rel.status,
        "root": rel.root_uri,
        "manifest_sha256": rel.manifest_sha256,
        "created_at": rel.created_at,
        "published_at": rel.published_at,
        "items": dict(items),
        "preset": (rel.parameters or {}).get("preset"),
        "pair_params": (rel.parameters or {}).get("pair_params"),
        "pairs": (rel.parameters or {}).get("pairs"),
        # the change radius of each pair: a smaller change is labelled unchanged
        "smallest_change_m": (rel.parameters or {}).get("smallest_change_m"),
        "radius_ceiling_m": (rel.parameters or {}).get("radius_ceiling_m"),
        # where the ignore pixels come from, by cause (releases built before causes were recorded: None)
        "ignore": (rel.parameters or {}).get("ignore"),
        # per pair, its changed regions and the views that show each (releases built before: None)
        "changes_seen": (rel.parameters or {}).get("changes_seen"),
    }


def record_draft(session: Session, draft: DraftRelease, folders: tuple[str, ...], run: StageRun) -> None:
    """Record a draft written whole at ``draft.root``: the release row (created, or rewritten for a
    rebuilt draft) and one item row per item (``folders``: the layout's folders, for each item's
    files), linked to the view rows of the outputs it drew on, and the stage run."""
    rel = find_release(session, draft.name, draft.version)
    if rel is None:
        rel = Release(name=draft.name, version=draft.version)
        session.add(rel)
    rel.status = "draft"
    rel.parameters = draft.parameters
    rel.root_uri = draft.root
    rel.manifest_sha256 = draft.manifest_sha256
    session.flush()
    session.execute(sa.delete(ReleaseItem).where(ReleaseItem.release_id == rel.id))
    view_ids = {pid: pair_view_ids(session, pid, digest) for pid, digest in draft.digests.items()}
    for it in draft.items:
        session.add(
            ReleaseItem(
                release_id=rel.id, item_id=it.id, pair_id=it.pair, view_id=view_ids[it.pair].get(it.view),
                split=it.split, coverage=it.coverage, change_ratio=it.change_ratio, change_visible=it.change_visible,
                files={sub: f"{it.split}/{sub}/{it.id}.png" for sub in folders},
            )
        )  # fmt: skip
    add_completed(session, run)


def superseded_pairs(session: Session, rel: Release) -> list[int]:
    """The pairs release ``rel`` was built from that a scene ingested between their scenes has
    superseded since (they are no longer consecutive)."""
    return [
        pid
        for pid in (rel.parameters or {}).get("pairs", [])
        if get_pair(session, pid).status == "superseded"
    ]


def refuse_superseded(session: Session, rel: Release) -> None:
    """:class:`ReleaseError` when release ``rel`` was built from a pair superseded since."""
    gone = superseded_pairs(session, rel)
    if gone:
        raise ReleaseError(
            f"release {rel.name} {rel.version} was built from pair(s) {', '.join(map(str, gone))}, superseded since "
            "(a scene was ingested between their scenes): its pairs are no longer consecutive. Build it "
            "again (`siteline release build`); nothing was published."
        )


def record_published(
    session: Session, name: str, version: str, root: Path, run: StageRun
) -> tuple[int, str | None]:
    """Mark release ``name`` ``version`` published at ``root`` (the draft folder already renamed there)
    and record the stage run; return its item count and manifest sha256. The site's row is locked
    first, as an ingest locks it to form its pairs, and the release refused if one of its pairs was
    superseded meanwhile (an ingest that committed while the draft was checked and moved)."""
    rel = get_release(session, name, version)
    pairs = (rel.parameters or {}).get("pairs", [])
    if pairs:
        lock_site(session, get_pair(session, pairs[0]).site_id)
        session.expire_all()  # read the pairs as the lock leaves them
        rel = get_release(session, name, version)
    refuse_superseded(session, rel)
    rel.status = "published"
    rel.published_at = datetime.now(UTC)
    rel.root_uri = str(root)
    add_completed(session, run)
    return sum(release_item_counts(session, rel.id).values()), rel.manifest_sha256


def remove_draft(session: Session, name: str, version: str) -> None:
    """Delete the draft release ``name`` ``version`` and its items (a published one is refused by
    the flush guards)."""
    session.delete(get_release(session, name, version))


def release_location(session: Session, name: str, version: str) -> tuple[Path, str]:
    """Where release ``name`` ``version`` lives and its status (draft or published)."""
    rel = get_release(session, name, version)
    if rel.root_uri is None:
        raise NotFoundError(f"release {name} {version} has no folder recorded; build it again.")
    return Path(rel.root_uri), rel.status


def query_items(
    session: Session,
    name: str,
    version: str,
    min_change_ratio: float | None = None,
    split: str | None = None,
    since: datetime | None = None,
    until: datetime | None = None,
    min_change_visible: float | None = None,
) -> list[dict]:
    """Items of a release with a change ratio above a threshold, of a split, whose pair's scenes
    were captured in [since, until], or whose changed pixels show their change at least
    ``min_change_visible`` (items with nothing changed, or not measured, are left out then)."""
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
    if min_change_visible is not None:
        q = q.where(ReleaseItem.change_visible >= min_change_visible)
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
            "change_visible": it.change_visible,
            "coverage": it.coverage,
            "t1_time": a,
            "t2_time": b,
            "files": it.files,
        }
        for it, a, b in session.execute(q).all()
    ]
