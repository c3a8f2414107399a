"""``siteline labels ...``: label-set versions of a scene (import corrected labels, list, show, diff)."""

from __future__ import annotations

import os
import uuid
from datetime import UTC, datetime
from pathlib import Path

import typer

from siteline.catalog.context import StageContext
from siteline.cli.common import (
    JsonOption,
    catalog,
    console,
    emit,
    print_record,
    print_table,
    progress_bars,
    settings,
)
from siteline.schema import json_object

app = typer.Typer(help="Label-set versions of a scene's semantic classes.", no_args_is_help=True)

IMPORTED = "siteline.labels.imported"


def imported_event(scene_id: int, version: int, site: str) -> dict:
    """The event announcing a new label-set version (Prefect's event schema); the
    process-scene-pairs deployment re-processes the scene's pairs on it."""
    return {
        "id": str(uuid.uuid4()),
        "occurred": datetime.now(UTC).isoformat(),
        "event": IMPORTED,
        "resource": {
            "prefect.resource.id": f"siteline.labelset.{scene_id}.{version}",
            "siteline.site.spec": site,
        },
        "payload": {"scene_id": scene_id, "version": version, "site": site},
        "related": [],
    }


@app.command("import")
def import_cmd(
    scene_id: int = typer.Argument(..., help="Scene id the file was exported from."),
    file: Path = typer.Argument(..., help="Corrected LAS/LAZ file (e.g. from `siteline scene export`)."),
    taxonomy_map: str | None = typer.Option(
        None,
        "--taxonomy-map",
        help="How to read the file's class codes: a JSON file mapping them to site "
        'classes ({"2": "ground"}), "las" (the site taxonomy\'s LAS codes, e.g. ASPRS) or "site" (site class ids; '
        "needed when the file lost the record `scene export` writes).",
    ),
    note: str | None = typer.Option(None, "--note", help="What was corrected (kept with the version)."),
    max_unmatched: float | None = typer.Option(
        None,
        "--max-unmatched",
        help="Refuse when more than this fraction of the file's points match no scene point or repeat one "
        "(default 0.001).",
    ),
    announce: bool = typer.Option(
        True,
        "--announce/--no-announce",
        help="Post siteline.labels.imported to the Prefect API when PREFECT_API_URL is set (re-processes pairs).",
    ),
    as_json: bool = JsonOption,
) -> None:
    """Import corrected classes as the scene's next label-set version (nothing changes on refusal)."""
    from siteline.catalog.scenes import site_name_of_scene
    from siteline.labelsets.execute import DEFAULT_MAX_UNMATCHED
    from siteline.labelsets.mapping import parse_taxonomy_map
    from siteline.labelsets.stage import ImportOptions, import_labels

    mapping = parse_taxonomy_map(taxonomy_map) if taxonomy_map else None
    limit = DEFAULT_MAX_UNMATCHED if max_unmatched is None else max_unmatched
    with catalog() as cat, progress_bars(as_json, "count") as bars:
        result = import_labels(
            StageContext(cat, settings(), progress=bars), scene_id, file, ImportOptions(mapping, note, limit)
        )
        with cat.transaction() as s:
            site = site_name_of_scene(s, scene_id)
    announced = None
    url = os.environ.get("PREFECT_API_URL")
    if announce and url and result.created:
        from siteline.cli.watch import post_events

        post_events(url, [imported_event(scene_id, result.version, site)])
        announced = IMPORTED
    record = result.to_dict() | {"announced": announced}

    def human() -> None:
        if not result.created:
            console.print(
                f"scene {scene_id}: {file.name} changes no point's class ({result.matched:,} of "
                f"{result.points_in_file:,} points matched): no new version, label set {result.version} stays."
            )
            return
        console.print(
            f"scene {scene_id}: label set {result.version} from {file.name} ({result.matched:,} of "
            f"{result.points_in_file:,} points matched, {result.changed:,} changed class, "
            f"{result.untouched:,} scene points not in the file kept version {result.parent_version})"
        )
        for pair, n in list(result.changes.items())[:10]:
            console.print(f"  {pair}: {n:,}")
        if announced:
            console.print(f"announced {IMPORTED}: the scene's pairs will be processed again")

    emit(as_json, record, human)


@app.command("list")
def list_cmd(scene_id: int = typer.Argument(..., help="Scene id."), as_json: bool = JsonOption) -> None:
    """The scene's label-set versions."""
    from siteline.catalog.labelsets import label_set_record, label_sets
    from siteline.catalog.scenes import get_scene

    with catalog() as cat, cat.transaction() as s:
        get_scene(s, scene_id)
        rows = [label_set_record(r) for r in label_sets(s, scene_id)]
    emit(
        as_json,
        rows,
        lambda: print_table(
            f"label sets of scene {scene_id}",
            ["version", "from", "source", "changed points", "note", "created"],
            [
                [
                    r["version"],
                    r["parent_version"],
                    r["source"],
                    r["changed_points"],
                    r["note"],
                    r["created_at"],
                ]
                for r in rows
            ],
        ),
    )


@app.command("show")
def show_cmd(
    scene_id: int = typer.Argument(..., help="Scene id."),
    version: int | None = typer.Argument(None, help="Version (default: the newest)."),
    as_json: bool = JsonOption,
) -> None:
    """One label-set version: source file and checksum, note, class counts, matching statistics."""
    from siteline.catalog.labelsets import label_set, label_set_record
    from siteline.catalog.scenes import get_scene

    with catalog() as cat, cat.transaction() as s:
        get_scene(s, scene_id)
        record = label_set_record(label_set(s, scene_id, version))
    emit(as_json, record, lambda: print_record(f"scene {scene_id} label set {record['version']}", record))


@app.command("diff")
def diff_cmd(
    scene_id: int = typer.Argument(..., help="Scene id."),
    v1: int | None = typer.Argument(None, help="Older version (default: the newest's parent)."),
    v2: int | None = typer.Argument(None, help="Newer version (default: the newest)."),
    as_json: bool = JsonOption,
) -> None:
    """Points whose class differs between two versions, per (old class -> new class)."""
    from siteline.catalog.labelsets import label_set, labelled_source
    from siteline.catalog.scenes import get_scene
    from siteline.catalog.sites import site_of
    from siteline.labelsets.compare import diff_tiles
    from siteline.labelsets.store import open_labelled

    with catalog() as cat, cat.transaction() as s:
        taxonomy = site_of(s, get_scene(s, scene_id).site_id).taxonomy
        newer = label_set(s, scene_id, v2)
        older = label_set(s, scene_id, v1 if v1 is not None else (newer.parent_version or newer.version))
        (source, ref_a), (_, ref_b) = (labelled_source(s, scene_id, r.version) for r in (older, newer))
    va, vb = ref_a.version, ref_b.version
    record = {
        "scene": scene_id,
        "from": va,
        "to": vb,
        **diff_tiles(open_labelled(source, ref_a), open_labelled(source, ref_b), taxonomy),
    }

    def human() -> None:
        console.print(
            f"scene {scene_id}: label set {va} -> {vb}: {record['changed']:,} of {record['points']:,} points changed class"
        )
        print_table(
            "changed points",
            ["old -> new", "points"],
            [[k, f"{n:,}"] for k, n in json_object(record["changes"]).items()],
        )

    emit(as_json, record, human)
