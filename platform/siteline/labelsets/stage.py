"""The label-set import stage: plan (catalog) -> execute (match the file, publish the store) ->
record (catalog)."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import sqlalchemy as sa

from siteline.catalog.context import StageContext
from siteline.catalog.labelsets import record_label_set
from siteline.errors import LabelSetError
from siteline.labelsets.execute import DEFAULT_MAX_UNMATCHED, execute_label_import
from siteline.labelsets.mapping import TaxonomyMap
from siteline.labelsets.plan import ImportPlan, plan_label_import
from siteline.pointpass import open_las, read_labels_vlr
from siteline.records.labelsets import ExportedLabels, LabelSetImport
from siteline.records.runs import StageRun
from siteline.stores import layout

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ImportOptions:
    """How a labels file is imported. ``taxonomy_map``: how its codes read (siteline.labelsets.mapping;
    None: site class ids, vouched for by the record ``scene export`` writes). ``note``: recorded with
    the version. ``max_unmatched``: the share of its points that may match nothing, or a point
    already taken, before it is refused. ``carried``: the file holds a whole label set exported before
    the scene was tiled again, imported over label set 1 (what the new tiles hold) rather than merged
    onto the newest."""

    taxonomy_map: TaxonomyMap = None
    note: str | None = None
    max_unmatched: float = DEFAULT_MAX_UNMATCHED
    carried: bool = False


def import_labels(
    ctx: StageContext,
    scene_id: int,
    path: Path,
    options: ImportOptions = ImportOptions(),
) -> LabelSetImport:
    """Import the classes of ``path`` as the next label-set version of ``scene_id`` (``options``:
    :class:`ImportOptions`). Points are matched by position in tile quanta, GPS time and return
    number; refused (nothing written) when the file is of another scene, holds unknown codes, is
    unreadable, or when more than ``max_unmatched`` of its points match nothing or match a point
    already taken. The store is published whole before its catalog row is added."""
    path, max_unmatched, carried = Path(path), options.max_unmatched, options.carried
    if not path.is_file():
        raise LabelSetError(f"labels file {path} does not exist.")
    if not 0.0 <= max_unmatched < 1.0:
        raise LabelSetError(f"max_unmatched {max_unmatched}: use a fraction in [0, 1).")
    base = None if carried else exported_from(path, scene_id)
    with ctx.catalog.lock(f"scene:{scene_id}:labels"):  # one import per scene at a time: versions 2, 3, ...
        with ctx.catalog.transaction() as s:
            plan = plan_label_import(s, scene_id, base, 1 if carried else None)
        return _import(ctx, plan, path, options)


def exported_from(path: Path, scene_id: int) -> int | None:
    """The label-set version ``path`` was exported from, as its siteline record says (None: no
    record, or one of another scene, which the import refuses by name)."""
    with open_las(path) as reader:
        doc = read_labels_vlr(reader.header, path)
    about = ExportedLabels.from_dict(doc) if doc is not None else None
    return about.label_set_version if about is not None and about.scene == scene_id else None


def _import(
    ctx: StageContext, plan: ImportPlan, path: Path, options: ImportOptions,
) -> LabelSetImport:  # fmt: skip
    scene_id, taxonomy_map, note, max_unmatched = (
        plan.scene_id,
        options.taxonomy_map,
        options.note,
        options.max_unmatched,
    )
    run = StageRun(
        "import_labels", f"scene:{scene_id}", {"file": str(path), "version": plan.version}, run_id=ctx.run_id
    )
    store = ctx.settings.store
    result = execute_label_import(
        plan, path, store, layout.scratch(ctx.settings.home), taxonomy_map, note, max_unmatched, ctx.progress
    )
    if not result.created:
        return result
    try:
        with ctx.catalog.transaction() as s:
            record_label_set(s, result, run)
    except sa.exc.IntegrityError as exc:
        # a writer outside this lock recorded this version: its store is at the same address, keep it
        raise LabelSetError(
            f"scene {scene_id}: another import recorded label-set version {plan.version} meanwhile; import "
            f"{path} again."
        ) from exc
    except BaseException:
        store.remove(result.uri)
        raise
    log.info("scene %d: label set %d recorded from %s", scene_id, result.version, path.name)
    return result
