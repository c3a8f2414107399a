"""Planning a tiling: what the catalog says about a scene before its tiles are written."""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy.orm import Session

from siteline.catalog.missions import las_location
from siteline.catalog.scenes import get_scene
from siteline.catalog.sites import site_of
from siteline.errors import TileError
from siteline.pointpass import Correction
from siteline.records.mission import LasLocation
from siteline.records.scan import EIGHT_BIT
from siteline.records.tiling import SceneTiling
from siteline.site.crs import ZUnit
from siteline.site.spec import SiteSpec


@dataclass(frozen=True)
class TilingPlan:
    """Everything tiling a scene needs from the catalog: the scene and its site, where its point
    cloud is kept, the source CRS and z unit ingest recorded, whether the scene is tiled, the tiling
    last recorded, if any, the seed of the level-of-detail draw (from the cloud's content), and
    whether its colour is 0-255 in 16-bit fields as ingest judged it (None: no colour, or not
    recorded), and the co-registration onto the previous scene that ingest applied (None: none)."""

    scene_id: int
    site: SiteSpec
    las: LasLocation
    source_crs: str | None
    z_unit: ZUnit | None
    tiled: bool
    current: SceneTiling | None
    seed: int
    eight_bit: bool | None = None
    correction: Correction | None = None

    @property
    def stale(self) -> bool:
        """Whether the recorded tiling mapped classes under an earlier version of the site (its
        taxonomy or fence changed since): it is tiled again."""
        return self.current is not None and self.current.site_version != self.site.version

    def generation(self, retile: bool) -> int:
        """The generation a tiling written now gets: the next one for a re-tiling (the old store stays
        until the new one is recorded), else the recorded one (0 for a scene never tiled)."""
        return (self.current.generation if self.current is not None else 0) + int(retile)

    def already_tiled(self) -> str:
        """The sentence for a scene that is tiled and complete."""
        assert self.current is not None
        hint = ""
        if not self.current.spec.partial_levels:
            hint = (
                " Its store keeps input order inside its nodes, so views read whole levels (up to 4x the "
                f"points they need): `siteline scene tile {self.scene_id} --retile` tiles it again in the "
                "current layout."
            )
        return f"scene {self.scene_id} is already tiled at {self.current.uri}: nothing to do.{hint}"


def plan_tiling(session: Session, scene_id: int) -> TilingPlan:
    """The plan of tiling scene ``scene_id`` (one transaction, no I/O beyond it)."""
    scene = get_scene(session, scene_id)
    stats = scene.statistics
    if stats.scan is None:
        raise TileError(f"scene {scene_id} records no point cloud scan: ingest its mission again.")
    return TilingPlan(
        scene_id=scene_id,
        site=site_of(session, scene.site_id),
        las=las_location(session, scene_id),
        source_crs=stats.scan.source_crs or None,
        z_unit=stats.scan.z_unit,
        tiled=scene.status == "tiled",
        current=stats.tiling,
        seed=stats.scan.content_seed(),
        eight_bit=EIGHT_BIT.get(stats.scan.colour),
        correction=scene.registration.correction,
    )
