"""``siteline site ...``: create, list and show sites."""

from __future__ import annotations

from pathlib import Path

import typer

from siteline.catalog.sites import add_site, get_site, list_sites, scene_count, site_record
from siteline.cli.common import JsonOption, catalog, console, emit, print_record, print_table
from siteline.fence import load_fence_geojson
from siteline.site import DEFAULT_TILE_SIZE_M, make_site_spec
from siteline.taxonomy import load_taxonomy

app = typer.Typer(help="Construction sites: CRS, origin, fence, taxonomy.", no_args_is_help=True)


@app.command("create")
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
) -> None:
    """Register a new site; every input is validated before anything is written."""
    fence_m = None
    if fence is not None:
        fence_m = load_fence_geojson(fence, origin)
        fence_m = [*fence_m, fence_m[0]]
    tax = load_taxonomy(taxonomy) if taxonomy is not None else None
    spec = make_site_spec(name, crs, origin, fence_m, tax, tile_size_m)
    with catalog() as cat, cat.transaction() as session:
        row = add_site(session, spec)
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
                    " ".join(f"{v:.3f}" for v in r["origin"]),
                    f"{r['fence_area_m2']:.0f}" if r["fence_area_m2"] else "-",
                    r["scenes"],
                ]
                for r in records
            ],
        ),
    )


@app.command("show")
def show(name: str = typer.Argument(..., help="Site name."), as_json: bool = JsonOption) -> None:
    """Show one site."""
    with catalog() as cat, cat.transaction() as session:
        site = get_site(session, name)
        record = site_record(site, scene_count(session, site))
    emit(as_json, record, lambda: print_record(f"site {name}", record))
