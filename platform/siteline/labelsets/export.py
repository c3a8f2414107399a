"""Exporting a scene with the classes of one of its label sets, for correction in a LAS editor."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from siteline.catalog import Catalog
from siteline.catalog.labelsets import labelled_source
from siteline.catalog.scenes import get_scene
from siteline.catalog.sites import site_of
from siteline.labelsets.store import open_labelled
from siteline.pointpass import write_changed_classes
from siteline.records.labelsets import ExportedLabels
from siteline.schema import json_doc
from siteline.tiles.export import export_las


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
        site = site_of(s, get_scene(s, scene_id).site_id)
        source, label_set = labelled_source(s, scene_id, version)
    about = ExportedLabels(
        site.name, scene_id, label_set.version, "site class ids", json_doc(site.taxonomy.to_dict())
    )
    tiles = open_labelled(source, label_set)
    return export_las(tiles, site, out, bounds=bounds, level=level, labels=about), label_set.version


def export_corrections(
    catalog: Catalog, scene_id: int, version: int, out: Path, chunk: int = 1_000_000
) -> int:
    """Write to ``out`` only the points whose class in label set ``version`` differs from label set 1
    (the corrections an import made), with that version's classes and siteline record; return how
    many. Both versions are exported beside ``out`` and read in step, chunk by chunk (the same tiles,
    the same point order), so memory stays bounded by ``chunk``."""
    first, corrected = out.with_name(f".{out.stem}.v1.laz"), out.with_name(f".{out.stem}.v{version}.laz")
    n = 0
    try:
        export_label_set(catalog, scene_id, first, 1)
        export_label_set(catalog, scene_id, corrected, version)
        n = write_changed_classes(first, corrected, out, chunk)
    finally:
        first.unlink(missing_ok=True)
        corrected.unlink(missing_ok=True)
    return n
