"""``siteline ingest``, ``siteline mission ...``, ``siteline scene ...``, ``siteline photo inspect``."""

from __future__ import annotations

from dataclasses import asdict
from datetime import datetime
from pathlib import Path

import typer

from siteline.camera.photos import read_photo_meta
from siteline.catalog.context import StageContext
from siteline.catalog.missions import list_missions
from siteline.catalog.pairs import list_pairs
from siteline.catalog.scenes import scene_record, scene_table
from siteline.catalog.sites import get_site
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
from siteline.errors import MissionError
from siteline.schema import json_object


def parse_time(text: str, option: str) -> datetime:
    """An ISO 8601 time with a zone (``Z`` for UTC); MissionError naming ``option`` otherwise."""
    try:
        when = datetime.fromisoformat(text.strip())
    except ValueError as exc:
        raise MissionError(f"{option} {text!r} is not an ISO 8601 time (e.g. 2024-11-27T16:31:00Z).") from exc
    if when.tzinfo is None:
        raise MissionError(f"{option} {text!r} has no time zone: add one (Z for UTC, or +01:00).")
    return when


mission_app = typer.Typer(help="Ingested missions.", no_args_is_help=True)
scene_app = typer.Typer(help="Scenes (epochs) of a site.", no_args_is_help=True)
photo_app = typer.Typer(help="DJI photo metadata.", no_args_is_help=True)


def ingest(
    mission_dir: Path = typer.Argument(
        ..., help="DJI mission folder (raw SD-card folder, lidars/terra_las/, photos, COLMAP model)."
    ),
    site: str = typer.Option(..., "--site", help="Site the mission belongs to."),
    crs: str | None = typer.Option(
        None,
        "--crs",
        help="CRS of a LAS file that records none, e.g. EPSG:2994: any CRS, feet included; points "
        "are transformed into the site CRS.",
    ),
    z_unit: str | None = typer.Option(
        None,
        "--z-unit",
        help="Unit of the file's z: m, ft or ftUS (default: its vertical CRS, else its horizontal unit).",
    ),
    copy: bool = typer.Option(
        True,
        "--copy/--reference",
        help="Copy files into the content-addressed store, or reference them in place.",
    ),
    accept_misalignment: bool = typer.Option(
        False,
        "--accept-misalignment",
        help="Register the scene even when ICP finds it misaligned with the previous one.",
    ),
    max_rms_m: float = typer.Option(
        0.1, "--max-georegistration-rms-m", help="Largest accepted georegistration RMS, metres."
    ),
    workers: int = typer.Option(
        2,
        "--workers",
        help="Processes reading the point cloud (in point ranges) and writing tiles (each owns whole tiles).",
    ),
    captured_at: str | None = typer.Option(
        None,
        "--captured-at",
        help="Capture time, ISO 8601 with a zone (2024-11-27T16:31:00Z), for a mission that cannot tell it "
        "(a LiDAR-only LAS without a creation date); overrides the photos' time. Recorded as given.",
    ),
    plan_cameras: bool = typer.Option(
        False,
        "--plan-cameras",
        help="Plan the cameras from the point cloud even when the mission has "
        "photos (a mission without photos always gets planned cameras).",
    ),
    camera: str = typer.Option(
        "zenmuse-l2",
        "--camera",
        help="Camera of planned cameras: zenmuse-l2, zenmuse-p1-35mm, or a JSON "
        "file of width, height, fx (fy, cx, cy) in pixels.",
    ),
    altitude_m: float | None = typer.Option(
        None,
        "--altitude",
        help="Planned cameras' height above the ground, metres (default: the scene's tallest structure plus "
        "--clearance, raised to what its density and area ask, 20-120 m; one under the tallest structure is refused).",
    ),
    clearance_m: float = typer.Option(
        15.0,
        "--clearance",
        help="How far over the scene's tallest structure (a crane, a roof: the highest kept surface above the "
        "ground under it) a chosen altitude flies, metres.",
    ),
    overlap: tuple[float, float] = typer.Option(
        (0.7, 0.6), "--overlap", help="Planned survey's forward and side overlap (0-0.95)."
    ),
    oblique_pitch: float = typer.Option(
        45.0, "--oblique-pitch", help="Planned oblique cameras' tilt below the horizontal, degrees (0: none)."
    ),
    unmapped_codes: str = typer.Option(
        "refuse",
        "--unmapped-codes",
        help="Class codes the site taxonomy does not map: refuse the file "
        "(naming them) or make their points ignore.",
    ),
    as_json: bool = JsonOption,
) -> None:
    """Ingest a mission folder (or one LAS/LAZ file) as a new scene of a site and tile it (a re-run of the
    same content does nothing)."""
    from siteline import pipeline
    from siteline.camera.intrinsics import camera_model
    from siteline.ingest.options import IngestOptions
    from siteline.register.planned import SurveyPlan

    survey = SurveyPlan(camera_model(camera), altitude_m, overlap[0], overlap[1], oblique_pitch, clearance_m)
    opts = IngestOptions(
        plan_cameras=plan_cameras,
        survey=survey,
        captured_at=parse_time(captured_at, "--captured-at") if captured_at else None,
        crs=crs,
        z_unit=z_unit,
        storage="copy" if copy else "reference",
        accept_misalignment=accept_misalignment,
        max_georegistration_rms_m=max_rms_m,
        unmapped_codes=unmapped_codes,
    )
    with catalog() as cat, progress_bars(as_json, "bytes") as bars:
        done = pipeline.ingest(
            StageContext(cat, settings(), progress=bars), mission_dir, site, opts, workers=workers
        )
    emit(as_json, done.to_dict(), lambda: console.print(done.summary()))


@mission_app.command("list")
def mission_list(
    site: str | None = typer.Option(None, "--site", help="Only this site."), as_json: bool = JsonOption
) -> None:
    """List ingested missions."""
    with catalog() as cat, cat.transaction() as s:
        rows = list_missions(s, get_site(s, site) if site else None)
        records: list[dict[str, object]] = [
            {
                "id": m.id,
                "site_id": m.site_id,
                "name": m.name,
                "manifest_sha256": m.manifest_sha256,
                "received_at": m.received_at,
                "status": m.status,
                "storage": m.storage,
                "root": m.root_uri,
            }
            for m in rows
        ]
        table = [[m.id, m.name, m.status, m.storage, m.received_at, m.manifest_sha256[:12]] for m in rows]
    emit(
        as_json,
        records,
        lambda: print_table(
            "missions",
            ["id", "name", "status", "storage", "received", "manifest"],
            table,
        ),
    )


@scene_app.command("list")
def scene_list(
    site: str = typer.Option(..., "--site", help="Site name."), as_json: bool = JsonOption
) -> None:
    """List the scenes of a site in capture order, and its pairs."""
    with catalog() as cat, cat.transaction() as s:
        st = get_site(s, site)
        records = scene_table(s, st)
        pairs = [{"id": p.id, "t1": p.t1_scene_id, "t2": p.t2_scene_id} for p in list_pairs(s, st)]

    def human() -> None:
        rows = [
            [r["id"], r["capture_time"], f"{r['points']:,}", r["status"], r["registration"],
             "" if r["alignment_m"] is None else f"{r['alignment_m']:.3f}"]
            for r in records
        ]  # fmt: skip
        print_table(
            f"scenes of {site}", ["id", "captured", "points", "status", "cameras from", "ICP shift m"], rows
        )
        print_table("pairs", ["id", "t1", "t2"], [[p["id"], p["t1"], p["t2"]] for p in pairs])

    emit(as_json, {"site": site, "scenes": records, "pairs": pairs}, human)


@scene_app.command("show")
def scene_show(scene_id: int = typer.Argument(..., help="Scene id."), as_json: bool = JsonOption) -> None:
    """Show one scene: statistics, registration, tiles."""
    with catalog() as cat, cat.transaction() as s:
        record = scene_record(s, scene_id)
    emit(as_json, record, lambda: print_record(f"scene {scene_id}", record))


@photo_app.command("inspect")
def photo_inspect(
    file: Path = typer.Argument(..., help="A DJI photo (JPEG)."), as_json: bool = JsonOption
) -> None:
    """Print the DJI XMP (or EXIF) metadata siteline reads from a photo."""
    meta = read_photo_meta(file)
    record = meta.to_dict()
    sources = json_object(record.pop("sources"), "sources")
    rows = [(k, v, sources.get(k, "")) for k, v in record.items() if v is not None]
    emit(
        as_json,
        {**record, "sources": sources},
        lambda: print_table(f"photo {file.name}", ["field", "value", "read from"], rows),
    )


@scene_app.command("tile")
def scene_tile(
    scene_id: int = typer.Argument(..., help="Scene id."),
    workers: int = typer.Option(2, "--workers", help="Processes writing tiles."),
    retile: bool = typer.Option(
        False,
        "--retile",
        help="Tile a tiled scene again in the current layout (a store written before node prefixes "
        "spanned their nodes reads up to 4x the points a view needs). Its pairs are then processed again, and "
        "imported label sets must be imported again.",
    ),
    as_json: bool = JsonOption,
) -> None:
    """Tile a registered scene into its Zarr store (a scene already tiled is left alone unless --retile)."""
    from siteline.pointpass import TilingResources
    from siteline.tiles.stage import tile_scene

    cfg = settings()
    with catalog() as cat, progress_bars(as_json) as bars:
        done = tile_scene(
            StageContext(cat, cfg, progress=bars), scene_id, resources=TilingResources(workers), retile=retile
        )
    emit(
        as_json,
        {"message": done.message, "tiles": done.tiling.to_dict() if done.tiling else None},
        lambda: console.print(done.message),
    )


@scene_app.command("export")
def scene_export(
    scene_id: int = typer.Argument(..., help="Scene id."),
    out: Path = typer.Option(..., "--out", help="Output .las or .laz file."),
    bounds: list[float] | None = typer.Option(
        None, "--bounds", help="xmin ymin xmax ymax (site-local metres); repeat 4 times."
    ),
    level: int | None = typer.Option(None, "--level", help="Deepest level of detail (default: all)."),
    label_set: int | None = typer.Option(
        None, "--label-set", help="Label-set version whose classes to write (default: the newest)."
    ),
    as_json: bool = JsonOption,
) -> None:
    """Export a tiled scene (or a region, or coarse levels) to LAS/LAZ in the site CRS, with the
    classes of a label set (site class ids, the taxonomy in a siteline VLR) for correction."""
    from siteline.labelsets.export import export_label_set

    with catalog() as cat:
        n, version = export_label_set(cat, scene_id, out, label_set, bounds or None, level)
    emit(
        as_json,
        {"out": str(out), "points": n, "label_set_version": version},
        lambda: console.print(f"wrote {n:,} points to {out} (classes of label set {version})"),
    )


def confirmed(yes: bool, what: str) -> None:
    """Go on with deleting ``what`` when ``--yes`` was given or a person at a terminal says so."""
    import sys

    if yes:
        return
    if not sys.stdin.isatty():
        raise typer.BadParameter(f"deleting {what} cannot be undone: pass --yes to confirm.")
    if not typer.confirm(f"delete {what}? This cannot be undone"):
        raise typer.Exit(1)


@scene_app.command("delete")
def scene_delete(
    scene_id: int = typer.Argument(..., help="Scene id."),
    yes: bool = typer.Option(False, "--yes", help="Do not ask (needed when not at a terminal)."),
    as_json: bool = JsonOption,
) -> None:
    """Delete a scene: its tiles, label sets, pairs (their outputs) and draft releases built on them, its
    mission and its rows; the scenes around it are paired again. Refused while a published release
    was built on one of its pairs."""
    from siteline import pipeline

    confirmed(yes, f"scene {scene_id}")
    with catalog() as cat:
        done = pipeline.delete_scene(cat, settings(), scene_id)
    emit(as_json, asdict(done), lambda: console.print(done.message(f"scene {scene_id}")))
