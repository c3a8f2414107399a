"""Exporting a scene with the classes of one of its label sets, for correction in a LAS editor."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from siteline.catalog import Catalog
from siteline.catalog.models import Site
from siteline.catalog.scenes import get_scene
from siteline.catalog.sites import site_spec
from siteline.labelsets.store import open_labelled_tiles
from siteline.tiles import export_las


def export_label_set(
    catalog: Catalog,
    scene_id: int,
    out: Path,
    version: int | None = None,
    bounds: Sequence[float] | None = None,
    level: int | None = None,
) -> tuple[int, int]:
    """Write scene ``scene_id`` (in ``bounds``, up to ``level``) to ``out`` with the classes of
    label-set ``version`` (None: the newest) as site class ids, and a siteline VLR saying what they
    mean (site, scene, version, taxonomy); return the point count and the version written."""
    with catalog.transaction() as s:
        scene = get_scene(s, scene_id)
        tiles, version = open_labelled_tiles(s, scene, version)
        spec = site_spec(s.get(Site, scene.site_id))
    about = {
        "site": spec.name,
        "scene": scene_id,
        "label_set_version": version,
        "classification": "site class ids",
        "taxonomy": spec.taxonomy.to_dict(),
    }
    return export_las(tiles, spec, out, bounds=bounds, level=level, labels=about), version
