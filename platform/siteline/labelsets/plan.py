"""Planning a label-set import: what the catalog says about the scene before the file is read."""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy.orm import Session

from siteline.catalog.labelsets import label_set_ref, label_sets, labelled_source
from siteline.catalog.scenes import get_scene
from siteline.catalog.sites import site_of
from siteline.records.labelsets import LabelSetRef
from siteline.records.tiling import TileSource
from siteline.site.spec import SiteSpec


@dataclass(frozen=True)
class ImportPlan:
    """What importing corrected labels into a scene needs: the scene and its site, its tiles, the
    version the import corrects (the newest), the version it would create, and the version the file
    was exported from (``base``: the parent unless the file's siteline record names an earlier one,
    whose changes are then merged onto the parent)."""

    scene_id: int
    site: SiteSpec
    tiles: TileSource
    parent: LabelSetRef
    version: int
    base: LabelSetRef | None = None

    @property
    def merging(self) -> bool:
        return self.base is not None and self.base.version != self.parent.version


def plan_label_import(
    session: Session, scene_id: int, base_version: int | None = None, parent_version: int | None = None
) -> ImportPlan:
    """The plan of importing labels into scene ``scene_id`` (one transaction), exported from label
    set ``base_version`` (None: unknown, taken as the parent), over label set ``parent_version``
    (None: the newest; 1 when corrections are carried onto a scene tiled again)."""
    scene = get_scene(session, scene_id)
    source, parent = labelled_source(session, scene_id, parent_version)
    version = max(r.version for r in label_sets(session, scene_id)) + 1
    base = parent
    if base_version is not None and base_version != parent.version:
        base = label_set_ref(session, scene_id, base_version)
    return ImportPlan(scene_id, site_of(session, scene.site_id), source, parent, version, base)
