"""``siteline bench trade``: measure the speed/accuracy trade on a synthetic site with known truth."""

from __future__ import annotations

from pathlib import Path

import typer

from siteline.cli.common import console

app = typer.Typer(help="Measurements.", no_args_is_help=True)


@app.command("trade")
def trade(
    site_density: float = typer.Option(
        10.0, "--site-density", help="Synthetic LiDAR density, points per m2."
    ),
    views: int = typer.Option(8, "--views", help="Views rendered per setting."),
    out: Path = typer.Option(
        Path("trade"), "--out", help="Output folder: trade.csv, trade.md, labels3d.csv, plots."
    ),
    seed: int = typer.Option(0, "--seed"),
    quick: bool = typer.Option(
        False, "--quick", help="A reduced grid (scale 1 and 1/4, radius x2.5) for a smoke run."
    ),
) -> None:
    """Sweep scale x point size x level of detail x label radius x nearest-neighbour backend."""
    from siteline.trade import TradeGrid, run_trade

    grid = (
        TradeGrid(scales=(1.0, 0.25), lod_factors=(1.0,), radius_multipliers=(2.5,)) if quick else TradeGrid()
    )
    rows = run_trade(out, site_density, views, seed, grid, progress=lambda m: console.print(m))
    console.print((out / "trade.md").read_text())
    console.print(f"{len(rows)} settings measured; CSV, tables and plots in {out}")
