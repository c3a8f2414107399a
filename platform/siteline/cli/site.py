"""``siteline site ...``: create, list and show sites."""

from __future__ import annotations

from pathlib import Path

import typer
from sqlalchemy.orm import Session

from siteline.catalog.context import StageContext
from siteline.catalog.sites import (
    add_site,
    get_site,
    list_sites,
    scene_count,
    set_release_settings,
    site_record,
)
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
from siteline.cli.knobs import with_knob_options
from siteline.errors import ReleaseError
from siteline.records.params.release import ReleaseKnobs
from siteline.schema import JSON, json_list
from siteline.site.fence import load_fence_geojson
from siteline.site.spec import DEFAULT_TILE_SIZE_M, make_site_spec
from siteline.site.taxonomy import default_taxonomy, load_taxonomy

app = typer.Typer(help="Construction sites: CRS, origin, fence, taxonomy.", no_args_is_help=True)


@app.command("create")
@with_knob_options
def create(
    name: str = typer.Argument(..., help="Site name (letters, digits, '_', '.', '-')."),
    crs: str = typer.Option(..., "--crs", help="Projected CRS in metres, e.g. EPSG:32618."),
    origin: tuple[float, float, float] = typer.Option(
        ..., "--origin", help="Site origin X Y Z in the CRS (float64)."
    ),
    fence: Path | None = typer.Option(None, "--fence", help="GeoJSON Polygon of the fence in the site CRS."),
    taxonomy: Path | None = typer.Option(
        None, "--taxonomy", help="Taxonomy JSON (schema/taxonomy.schema.json)."
    ),
    tile_size_m: float = typer.Option(DEFAULT_TILE_SIZE_M, "--tile-size-m", help="Tile grid edge, metres."),
    as_json: bool = JsonOption,
    *,
    knobs: ReleaseKnobs,
) -> None:
    """Register a new site with its release settings (the options below; unset knobs stay auto or at
    their defaults: docs in README 'Release settings'); every input is validated before anything is
    written."""
    fence_m = None
    if fence is not None:
        fence_m = load_fence_geojson(fence, origin)
        fence_m = [*fence_m, fence_m[0]]
    tax = load_taxonomy(taxonomy) if taxonomy is not None else None
    spec = make_site_spec(name, crs, origin, fence_m, tax, tile_size_m)
    with catalog() as cat, cat.transaction() as session:
        row = add_site(session, spec, knobs)
        record = site_record(row, 0)
    emit(
        as_json,
        record,
        lambda: console.print(f"created site {name} ({spec.crs}, origin {spec.origin})"),
    )


@app.command("list")
def list_(as_json: bool = JsonOption) -> None:
    """List every site."""
    with catalog() as cat, cat.transaction() as session:
        records = [site_record(s, scene_count(session, s)) for s in list_sites(session)]
    emit(
        as_json,
        records,
        lambda: print_table(
            "sites",
            ["name", "crs", "origin", "fence m2", "scenes"],
            [
                [
                    r["name"],
                    r["crs"],
                    " ".join(f"{v:.3f}" for v in json_list(r["origin"], "origin")),
                    f"{r['fence_area_m2']:.0f}" if r["fence_area_m2"] else "-",
                    r["scenes"],
                ]
                for r in records
            ],
        ),
    )


@app.command("show")
def show(name: str = typer.Argument(..., help="Site name."), as_json: bool = JsonOption) -> None:
    """Show one site, its stored release settings and what a release built now would use."""
    with catalog() as cat, cat.transaction() as session:
        site = get_site(session, name)
        record = site_record(site, scene_count(session, site)) | {"release_now": _release_now(session, name)}
    emit(as_json, record, lambda: print_record(f"site {name}", record))


@app.command("update")
@with_knob_options
def update(
    name: str = typer.Argument(..., help="Site name."),
    unset: list[str] | None = typer.Option(
        None,
        "--unset",
        help="A release setting to drop (back to auto or its default), e.g. scale (repeatable).",
    ),
    taxonomy: str | None = typer.Option(
        None,
        "--taxonomy",
        help="A new taxonomy JSON (or 'default'): a new site version; its scenes are tiled again.",
    ),
    fence: Path | None = typer.Option(
        None,
        "--fence",
        help="A new fence (GeoJSON Polygon in the site CRS): a new site version; scenes tiled again.",
    ),
    no_fence: bool = typer.Option(
        False, "--no-fence", help="Drop the fence (views judged against each scene's footprint)."
    ),
    workers: int = typer.Option(2, "--workers", help="Processes tiling each scene again."),
    as_json: bool = JsonOption,
    *,
    knobs: ReleaseKnobs,
) -> None:
    """Change a site's release settings (the options given are written over the stored ones; the next
    release build uses them, a changed knob makes a new major version), and its taxonomy or fence:
    the site's next version, under which its scenes are tiled again here (releases then record it)."""
    redefine = taxonomy is not None or fence is not None or no_fence
    if fence is not None and no_fence:
        raise typer.BadParameter("give --fence or --no-fence, not both.")
    tax = None
    if taxonomy is not None:
        tax = default_taxonomy() if taxonomy == "default" else load_taxonomy(Path(taxonomy))
    with catalog() as cat:
        with cat.transaction() as session:
            site = get_site(session, name)
            origin = site.spec.origin
            new = site.release_settings.updated(knobs, unset or ())
            set_release_settings(session, name, new)
        ring = None
        if fence is not None:
            ring = load_fence_geojson(fence, origin)
            ring = [*ring, ring[0]]
        lines = [f"site {name} release settings: {new.to_dict() or 'all defaults (auto)'}"]
        if redefine:
            from siteline import pipeline

            with progress_bars(as_json) as bars:
                version, tiled = pipeline.redefine_site(
                    StageContext(cat, settings(), progress=bars), name, tax, ring, no_fence, workers
                )
            lines += [f"site {name} is at version {version}", *(t.message for t in tiled)]
        with cat.transaction() as session:
            site = get_site(session, name)
            record = site_record(site, scene_count(session, site)) | {
                "release_now": _release_now(session, name)
            }
    emit(as_json, record, lambda: console.print("\n".join(lines)))


@app.command("delete")
def delete(
    name: str = typer.Argument(..., help="Site name."),
    yes: bool = typer.Option(False, "--yes", help="Do not ask (needed when not at a terminal)."),
    as_json: bool = JsonOption,
) -> None:
    """Delete a site with all its scenes, pairs, stores and draft releases; refused while a published
    release was built on one of its pairs."""
    from dataclasses import asdict

    from siteline import pipeline
    from siteline.cli.ingest import confirmed

    confirmed(yes, f"site {name} and all its scenes")
    with catalog() as cat:
        done = pipeline.delete_site(cat, settings(), name)
    emit(as_json, asdict(done), lambda: console.print(done.message(f"site {name}")))


def _release_now(session: Session, name: str) -> dict[str, JSON] | str:
    """The knobs a release of the site built now would use (auto ones worked out), or why none can."""
    from siteline.release.plan import release_params

    try:
        params = release_params(session, name, None, f"a release of site {name}")
    except ReleaseError as exc:
        return str(exc)
    keep = ("scale", "point_size_px", "views", "min_valid", "min_coverage", "lod_factor", "radius_m")
    return {k: params.pair.to_dict()[k] for k in keep} | {
        "preset": params.preset, "pad": params.pad, "min_image_px": params.min_image_px, "derived": dict(params.derived),
    }  # fmt: skip
