"""Planning a label-set import: what the catalog says about the scene before the file is read."""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy.orm import Session

from siteline.catalog.labelsets import label_sets, labelled_source
from siteline.catalog.scenes import get_scene
from siteline.catalog.sites import site_of
from siteline.records.labelsets import LabelSetRef
from siteline.records.tiling import TileSource
from siteline.site import SiteSpec


@dataclass(frozen=True)
class ImportPlan:
    """What importing corrected labels into a scene needs: the scene and its site, its tiles, the
    version the import corrects (the newest) and the version it would create."""

    scene_id: int
    site: SiteSpec
    tiles: TileSource
    parent: LabelSetRef
    version: int


def plan_label_import(session: Session, scene_id: int) -> ImportPlan:
    """The plan of importing labels into scene ``scene_id`` (one transaction)."""
    scene = get_scene(session, scene_id)
    source, parent = labelled_source(session, scene_id)
    version = max(r.version for r in label_sets(session, scene_id)) + 1
    return ImportPlan(scene_id, site_of(session, scene.site_id), source, parent, version)
