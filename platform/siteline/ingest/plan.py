"""Planning an ingest: what the catalog says about the site and the mission before the mission's
contents are read."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime

from sqlalchemy.orm import Session

from siteline.catalog.missions import mission_by_manifest
from siteline.catalog.scenes import list_scenes, scene_of_mission
from siteline.catalog.sites import get_site
from siteline.records.mission import MissionManifest
from siteline.records.scene import SceneView
from siteline.site.spec import SiteSpec


@dataclass(frozen=True)
class ExistingMission:
    """A mission with the same manifest already ingested into this site: its id and its scene's."""

    mission_id: int
    scene_id: int | None


@dataclass(frozen=True)
class IngestPlan:
    """What ingesting a mission into a site needs from the catalog: the site, the mission's manifest,
    the mission if it is already ingested, and the site's scenes (capture times, and the samples the
    alignment check compares against)."""

    site_id: int
    site: SiteSpec
    manifest: MissionManifest
    existing: ExistingMission | None
    scenes: tuple[SceneView, ...]

    def scene_at(self, when: datetime) -> SceneView | None:
        return next((sc for sc in self.scenes if sc.capture_time == when), None)

    def scene_before(self, when: datetime) -> SceneView | None:
        """The site's scene captured last before ``when``."""
        earlier = [sc for sc in self.scenes if sc.capture_time < when]
        return max(earlier, key=lambda sc: sc.capture_time) if earlier else None


def plan_ingest(session: Session, site_name: str, manifest: MissionManifest) -> IngestPlan:
    """The plan of ingesting the mission of ``manifest`` into ``site_name`` (one transaction); the
    same mission may be ingested into other sites too."""
    site = get_site(session, site_name)
    existing = mission_by_manifest(session, manifest.sha256, site.id)
    found = None
    if existing is not None:
        scene = scene_of_mission(session, existing.id)
        found = ExistingMission(existing.id, scene.id if scene is not None else None)
    return IngestPlan(site.id, site.spec, manifest, found, tuple(list_scenes(session, site)))
