"""Catalog queries on sites. Functions take a session and never commit: the caller owns the transaction."""

from __future__ import annotations

import sqlalchemy as sa
from sqlalchemy.orm import Session

from siteline.catalog.base import utcnow
from siteline.catalog.models import LabelSet, Scene, Site
from siteline.errors import NotFoundError, SiteError, SiteNotFoundError
from siteline.records.params.release import ReleaseKnobs
from siteline.records.site import SiteKey, SiteView
from siteline.schema import json_object
from siteline.site.fence import fence_area_m2
from siteline.site.spec import SiteSpec
from siteline.site.taxonomy import Taxonomy


def add_site(session: Session, spec: SiteSpec, release_settings: ReleaseKnobs | None = None) -> SiteView:
    """Insert a validated site with its release settings (siteline.release.knobs); :class:`SiteError`
    if the name is taken."""
    if session.execute(sa.select(Site.id).where(Site.name == spec.name)).first() is not None:
        raise SiteError(f"site {spec.name!r} already exists: choose another name (see `siteline site list`).")
    fence = None if spec.fence is None else [list(v) for v in spec.fence]
    row = Site(
        name=spec.name,
        crs=spec.crs,
        origin_x=spec.origin[0],
        origin_y=spec.origin[1],
        origin_z=spec.origin[2],
        fence=fence,
        taxonomy=spec.taxonomy.to_dict(),
        tile_size_m=spec.tile_size_m,
        release_settings=(release_settings or ReleaseKnobs()).to_dict(),
    )
    session.add(row)
    session.flush()
    return site_view(row)


def site_row(session: Session, name: str) -> Site:
    """The ORM row of site ``name`` (for the catalog's own writes); :class:`SiteNotFoundError` naming
    the known sites when there is none."""
    site = session.execute(sa.select(Site).where(Site.name == name)).scalar_one_or_none()
    if site is None:
        names = session.execute(sa.select(Site.name).order_by(Site.name)).scalars().all()
        hint = (
            f" Known sites: {', '.join(names)}." if names else " No site exists yet: `siteline site create`."
        )
        raise SiteNotFoundError(f"unknown site {name!r}.{hint}")
    return site


def set_release_settings(session: Session, name: str, release_settings: ReleaseKnobs) -> SiteView:
    """Store the site's release settings (siteline.release.knobs)."""
    site = site_row(session, name)
    site.release_settings = release_settings.to_dict()
    session.flush()
    return site_view(site)


def redefine_site(
    session: Session, name: str, taxonomy: Taxonomy | None, fence: list[list[float]] | None, clear_fence: bool
) -> tuple[SiteView, list[int]]:
    """Record site ``name``'s next version with ``taxonomy`` and/or ``fence`` (an open ring, site-local
    metres; ``clear_fence``: none) replacing the current ones, which go to its history; return it
    and its scenes (each to be tiled again). Refused, nothing changed, when a scene holds class codes
    the new taxonomy does not map."""
    site = session.execute(sa.select(Site).where(Site.name == name).with_for_update()).scalar_one_or_none()
    if site is None:
        site_row(session, name)  # names the known sites
        raise SiteNotFoundError(f"unknown site {name!r}.")
    if taxonomy is None and fence is None and not clear_fence:
        raise SiteError(f"site {name}: give --taxonomy, --fence or --no-fence to change.")
    scenes = list(
        session.execute(sa.select(Scene).where(Scene.site_id == site.id).order_by(Scene.id)).scalars()
    )
    if taxonomy is not None:
        _, known = taxonomy.code_lut("las") if "las" in taxonomy.source_codes else (None, None)
        for sc in scenes:
            codes = json_object((sc.statistics or {}).get("code_histogram") or {}, "code_histogram")
            missing = sorted(int(c) for c in codes if known is None or not known[int(c)])
            if missing:
                raise SiteError(
                    f"site {name}: taxonomy {taxonomy.name!r} does not map class codes {missing} of scene "
                    f"{sc.id}'s point cloud: add them to its 'las' source codes. Nothing was changed."
                )
    site.history = [
        *(site.history or []),
        {"version": site.version or 1, "taxonomy": site.taxonomy, "fence": site.fence, "replaced_at": utcnow().isoformat()},
    ]  # fmt: skip
    if taxonomy is not None:
        site.taxonomy = taxonomy.to_dict()
    if fence is not None or clear_fence:
        site.fence = fence
    site.version = (site.version or 1) + 1
    session.flush()
    return site_view(site), [sc.id for sc in scenes]


def imported_label_sets(session: Session, name: str) -> dict[int, int]:
    """Scene id -> its newest imported label-set version (above 1), for the scenes of site ``name``
    that have one."""
    site = site_row(session, name)
    rows = session.execute(
        sa.select(LabelSet.scene_id, sa.func.max(LabelSet.version))
        .join(Scene, Scene.id == LabelSet.scene_id)
        .where(Scene.site_id == site.id, LabelSet.version > 1)
        .group_by(LabelSet.scene_id)
    ).all()
    return {int(sid): int(v) for sid, v in rows}


def list_sites(session: Session) -> list[SiteView]:
    """Every site, by name."""
    return [site_view(s) for s in session.execute(sa.select(Site).order_by(Site.name)).scalars()]


def get_site(session: Session, name: str) -> SiteView:
    """Site ``name``; :class:`SiteNotFoundError` naming the known sites when there is none."""
    return site_view(site_row(session, name))


def site_view(site: Site) -> SiteView:
    """What the catalog hands out of a site row."""
    settings = ReleaseKnobs.from_dict(site.release_settings, f"site {site.name} release settings")
    return SiteView(site.id, site_spec(site), settings, site.created_at)


def site_spec(site: Site) -> SiteSpec:
    """The spec of a stored site."""
    fence = None if site.fence is None else tuple((float(x), float(y)) for x, y in site.fence)
    return SiteSpec(
        name=site.name,
        crs=site.crs,
        origin=site.origin,
        fence=fence,
        taxonomy=Taxonomy.from_dict(site.taxonomy, source=f"site {site.name} taxonomy"),
        tile_size_m=site.tile_size_m,
        version=site.version or 1,
    )


def site_of(session: Session, site_id: int) -> SiteSpec:
    """The spec of the site with id ``site_id``."""
    site = session.get(Site, site_id)
    if site is None:
        raise SiteNotFoundError(f"no site with id {site_id}.")
    return site_spec(site)


def site_record(site: SiteView, scenes: int) -> dict[str, object]:
    """A site as plain values (for the CLI): CRS, origin, fence and its area, classes, scenes."""
    spec = site.spec
    return {
        "name": spec.name,
        "crs": spec.crs,
        "origin": list(spec.origin),
        "fence_m": [list(v) for v in spec.fence] if spec.fence else None,
        "fence_area_m2": fence_area_m2(spec.fence) if spec.fence else None,
        "version": spec.version,
        "taxonomy": spec.taxonomy.name,
        "classes": {c.name: c.id for c in spec.taxonomy.classes},
        "tile_size_m": spec.tile_size_m,
        "release_settings": site.release_settings.to_dict(),
        "scenes": scenes,
        "created_at": site.created_at,
    }


def scene_count(session: Session, site: SiteKey) -> int:
    return session.execute(sa.select(sa.func.count(Scene.id)).where(Scene.site_id == site.id)).scalar_one()


def lock_site(session: Session, site_id: int) -> Site:
    """The site row, locked for the rest of the transaction (one registration, or one publish's
    re-check and record, per site at a time). SQLite ignores SELECT ... FOR UPDATE and opens no
    transaction for a read: there a no-op write to the row takes the database's write lock first,
    held until the transaction ends, so a concurrent ingest waits (busy timeout) as on PostgreSQL."""
    if session.get_bind().dialect.name == "sqlite":
        session.execute(sa.update(Site).where(Site.id == site_id).values(id=Site.id))
    return session.execute(sa.select(Site).where(Site.id == site_id).with_for_update()).scalar_one()


def site_name(session: Session, site_id: int) -> str:
    """The name of site ``site_id``; :class:`NotFoundError` when there is none."""
    site = session.get(Site, site_id)
    if site is None:
        raise NotFoundError(f"no site with id {site_id}.")
    return site.name
