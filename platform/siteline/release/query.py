"""Listing, comparing and querying releases from the catalog and their manifests."""

from __future__ import annotations

from datetime import datetime
from typing import Any

import sqlalchemy as sa
from sqlalchemy.orm import Session

from siteline.catalog.models import Pair, Release, ReleaseItem, Scene
from siteline.errors import NotFoundError
from siteline.release.manifest import read_manifest


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


def release_record(session: Session, rel: Release) -> dict[str, Any]:
    items = session.execute(
        sa.select(ReleaseItem.split, sa.func.count())
        .where(ReleaseItem.release_id == rel.id)
        .group_by(ReleaseItem.split)
    ).all()
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
    }


def list_releases(session: Session, name: str | None = None) -> list[Release]:
    q = sa.select(Release).order_by(Release.name, Release.created_at)
    if name:
        q = q.where(Release.name == name)
    return list(session.execute(q).scalars())


def _flat(d: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(d, dict):
        out = {}
        for k, v in d.items():
            out.update(_flat(v, f"{prefix}.{k}" if prefix else str(k)))
        return out
    return {prefix: d}


def diff_releases(session: Session, name: str, v1: str, v2: str) -> dict[str, Any]:
    """Pairs, parameters, label sets and files that differ between two versions."""
    a, b = get_release(session, name, v1), get_release(session, name, v2)
    ma, mb = read_manifest(a.root_uri), read_manifest(b.root_uri)
    pa = {p["id"]: p for p in ma["lineage"]["pairs"]}
    pb = {p["id"]: p for p in mb["lineage"]["pairs"]}
    fa = {f["path"]: f["sha256"] for f in ma["files"]}
    fb = {f["path"]: f["sha256"] for f in mb["files"]}
    flat_a, flat_b = _flat(ma["lineage"]["parameters"]), _flat(mb["lineage"]["parameters"])
    labels = {
        pid: {"radius_m": [pa[pid]["radius_m"], pb[pid]["radius_m"]]}
        for pid in sorted(set(pa) & set(pb))
        if pa[pid].get("radius_m") != pb[pid].get("radius_m")
        or pa[pid].get("labels", {}).get("checksum") != pb[pid].get("labels", {}).get("checksum")
    }
    return {
        "name": name,
        "from": v1,
        "to": v2,
        "pairs": {"added": sorted(set(pb) - set(pa)), "removed": sorted(set(pa) - set(pb))},
        "parameters": {
            k: [flat_a.get(k), flat_b.get(k)]
            for k in sorted(set(flat_a) | set(flat_b))
            if flat_a.get(k) != flat_b.get(k)
        },
        "label_sets": labels,
        "splits": {
            s: [ma["splits"][s], mb["splits"][s]]
            for s in ("train", "val", "test")
            if ma["splits"][s] != mb["splits"][s]
        },
        "files": {
            "added": sorted(set(fb) - set(fa)),
            "removed": sorted(set(fa) - set(fb)),
            "changed": sorted(p for p in set(fa) & set(fb) if fa[p] != fb[p]),
        },
    }


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
