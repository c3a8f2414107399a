"""Deleting scenes and sites from the catalog: what a deletion would remove (checked against the
releases that depend on it) and the rows it removes. Functions take a session and never commit."""

from __future__ import annotations

from dataclasses import dataclass

import sqlalchemy as sa
from sqlalchemy.orm import Session

from siteline.catalog.models import LabelSet, Mission, MissionFile, Pair, Release, ReleaseItem, Scene, Site
from siteline.catalog.pairs import ensure_pair
from siteline.catalog.scenes import neighbours, scene_row, scene_statistics
from siteline.catalog.sites import site_row
from siteline.errors import ImmutableError


@dataclass(frozen=True)
class Deletion:
    """What deleting ``scenes`` (and the site ``site``, when it goes too) removes: their pairs, the
    draft releases built on those pairs ((name, version)), the stores the rows name (tile stores,
    imported label sets), and the content-addressed blobs (sha256) no remaining mission or scene
    will name."""

    what: str
    scenes: tuple[int, ...]
    pairs: tuple[int, ...]
    drafts: tuple[tuple[str, str], ...]
    stores: tuple[str, ...]
    blobs: tuple[str, ...]
    site: str | None = None


def _pairs_of(session: Session, scene_ids: list[int]) -> list[int]:
    return list(
        session.execute(
            sa.select(Pair.id)
            .where(Pair.t1_scene_id.in_(scene_ids) | Pair.t2_scene_id.in_(scene_ids))
            .order_by(Pair.id)
        ).scalars()
    )


def _releases_of(session: Session, pair_ids: list[int]) -> list[Release]:
    return list(
        session.execute(
            sa.select(Release)
            .where(Release.id.in_(sa.select(ReleaseItem.release_id).where(ReleaseItem.pair_id.in_(pair_ids))))
            .order_by(Release.name, Release.id)
        ).scalars()
    )


def _blobs_left(session: Session, scenes: list[Scene]) -> list[str]:
    """The blobs of the scenes' missions and alignment samples that nothing outside them names."""
    mission_ids = [sc.mission_id for sc in scenes]
    shas = set(
        session.execute(
            sa.select(MissionFile.sha256).where(MissionFile.mission_id.in_(mission_ids))
        ).scalars()
    )
    shas |= {s for sc in scenes if (s := scene_statistics(sc).stable_sample_sha256)}
    kept = set(
        session.execute(
            sa.select(MissionFile.sha256).where(
                MissionFile.sha256.in_(shas), MissionFile.mission_id.not_in(mission_ids)
            )
        ).scalars()
    )
    others = session.execute(sa.select(Scene).where(Scene.id.not_in([sc.id for sc in scenes]))).scalars()
    kept |= {scene_statistics(sc).stable_sample_sha256 for sc in others} - {None}  # type: ignore[arg-type]
    return sorted(shas - kept)


def plan_deletion(session: Session, scene_ids: list[int], what: str, site: str | None = None) -> Deletion:
    """What deleting the scenes ``scene_ids`` (``what`` names them for messages) removes;
    :class:`ImmutableError` when a published release was built on one of their pairs."""
    scenes = [scene_row(session, sid) for sid in scene_ids]
    pairs = _pairs_of(session, scene_ids)
    releases = _releases_of(session, pairs) if pairs else []
    published = [f"{r.name} {r.version}" for r in releases if r.status == "published"]
    if published:
        raise ImmutableError(
            f"{what}: published release(s) {', '.join(published)} were built on its pairs and are never "
            "rewritten; their lineage names it. Nothing was deleted."
        )
    stores = [sc.tile_store_uri for sc in scenes if sc.tile_store_uri]
    stores += [
        uri
        for uri in session.execute(sa.select(LabelSet.uri).where(LabelSet.scene_id.in_(scene_ids))).scalars()
        if uri
    ]
    return Deletion(
        what, tuple(scene_ids), tuple(pairs), tuple((r.name, r.version) for r in releases), tuple(stores),
        tuple(_blobs_left(session, scenes)), site,
    )  # fmt: skip


def plan_scene_deletion(session: Session, scene_id: int) -> Deletion:
    return plan_deletion(session, [scene_id], f"scene {scene_id}")


def plan_site_deletion(session: Session, name: str) -> Deletion:
    site = site_row(session, name)
    ids = list(
        session.execute(sa.select(Scene.id).where(Scene.site_id == site.id).order_by(Scene.id)).scalars()
    )
    return plan_deletion(session, ids, f"site {name}", name)


def delete_rows(session: Session, deletion: Deletion) -> list[int]:
    """Remove the rows of ``deletion`` (after its stores are gone): the drafts built on its pairs, the
    pairs (views and renders with them), the scenes (cameras and label sets with them), their
    missions, and the site when it goes; for one scene of a site that keeps others, the scenes just
    before and after it are paired again. Returns the pairs made or restored by that."""
    scenes = [session.get(Scene, sid) for sid in deletion.scenes]
    live = [sc for sc in scenes if sc is not None]
    repaired: list[int] = []
    release_ids = [
        r.id
        for name, version in deletion.drafts
        if (r := session.execute(sa.select(Release).where(Release.name == name, Release.version == version)).scalar_one_or_none())
        and r.status != "published"
    ]  # fmt: skip
    session.execute(sa.delete(ReleaseItem).where(ReleaseItem.release_id.in_(release_ids)))
    session.execute(sa.delete(Release).where(Release.id.in_(release_ids)))
    for pid in deletion.pairs:
        pair = session.get(Pair, pid)
        if pair is not None:
            session.delete(pair)
    session.flush()
    for sc in live:
        mission = session.get(Mission, sc.mission_id)
        site = session.get(Site, sc.site_id)
        when = sc.capture_time
        session.delete(sc)
        session.flush()
        if mission is not None:
            session.delete(mission)
        if deletion.site is None and site is not None:
            before, after = neighbours(session, site, when)
            if before is not None and after is not None:
                pair = ensure_pair(session, site, before, after)
                pair.status = "new" if pair.status == "superseded" else pair.status
                repaired.append(pair.id)
    if deletion.site is not None:
        session.delete(site_row(session, deletion.site))
    session.flush()
    return repaired
