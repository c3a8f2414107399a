"""``siteline bench trade``: measure the speed/accuracy trade on a synthetic site with known truth."""

from __future__ import annotations

from pathlib import Path
from types import ModuleType

import typer

from siteline.cli.common import console

app = typer.Typer(help="Measurements.", no_args_is_help=True)


def _bench_trade() -> ModuleType:
    """``bench/trade.py`` of the source checkout: a benchmark, not part of the installed library."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[3] / "bench" / "trade.py"
    if not path.is_file():
        from siteline.errors import ConfigError

        raise ConfigError(
            f"siteline bench trade runs bench/trade.py from a source checkout of siteline; {path} is missing."
        )
    spec = importlib.util.spec_from_file_location("siteline_bench_trade", path)
    if spec is None or spec.loader is None:
        from siteline.errors import ConfigError

        raise ConfigError(f"{path} cannot be loaded as a Python module.")
    module = importlib.util.module_from_spec(spec)
    import sys

    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


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
    dense: bool = typer.Option(
        False,
        "--dense",
        help="The grid for paper density (use with --site-density 1000): scales 1/4 and 1/8, point "
        "sizes 1 and 3, LOD 1, 1.41 and 2, radius x2.5, pykdtree.",
    ),
    splats: bool = typer.Option(
        False,
        "--splats",
        help="Fixed disks against world splats with the gap fill, at scales 1 and 2 of the synthetic "
        "photos (1/8 and 1/4 of a Zenmuse L2 frame), point sizes 1 and 3, LOD 1, radius x2.5.",
    ),
) -> None:
    """Sweep scale x point size x splats x level of detail x label radius x nearest-neighbour backend."""
    trade_module = _bench_trade()
    TradeGrid, run_trade = trade_module.TradeGrid, trade_module.run_trade  # noqa: N806

    if quick + dense + splats > 1:
        raise typer.BadParameter("choose one of --quick, --dense and --splats.")
    grid = (
        trade_module.QUICK if quick else trade_module.DENSE if dense else trade_module.SPLATS if splats else TradeGrid()
    )
    rows = run_trade(out, site_density, views, seed, grid, progress=lambda m: console.print(m))
    console.print((out / "trade.md").read_text())
    console.print(f"{len(rows)} settings measured; CSV, tables and plots in {out}")
