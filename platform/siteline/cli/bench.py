"""``siteline bench trade``: the speed/accuracy trade of the pair knobs, measured on a synthetic site
against its analytic truth (siteline.trade)."""

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
    layout: str = typer.Option(
        "site",
        "--layout",
        help="site (the construction site), boxes (the analytic box scene with a turning jib) or slope "
        "(a sloped LiDAR-only scan: building, machine and tree that stay; car, stockpile, trench, pole, fence panel that change).",
    ),
    scan: str = typer.Option(
        "flown",
        "--scan",
        help="flown (an airborne scanner's lines, other lines each epoch) or sampled (every surface sampled alike, as before).",
    ),
    views: int = typer.Option(24, "--views", help="Views a pair."),
    grid: str = typer.Option(
        "full",
        "--grid",
        help="full (radius x1.5 and x4, fixed 1 and 3 px points, no gap fill, scale 1 and 2 (1/8 and 1/4 of an L2 frame on the synthetic photos), LOD x2) or quick (default, no gap fill).",
    ),
    variant: list[str] = typer.Option(
        [],
        "--variant",
        help="NAME=JSON pair knobs over the defaults, e.g. r3='{\"radius_multiplier\": 3}' (replaces --grid).",
    ),
    out: Path = typer.Option(
        Path("trade"), "--out", help="Output folder: the site, trade.json, trade.md, pictures."
    ),
    pictures: int = typer.Option(
        0, "--pictures", help="Save mask | truth | disagreement of this many views a variant."
    ),
    seed: int = typer.Option(0, "--seed"),
) -> None:
    """Each variant's masks scored per pixel against the ray-cast truth: precision, recall, F1, boundary F,
    each changed object's recall, specks per view, seconds."""
    from siteline.errors import ConfigError
    from siteline.trade import GRIDS, TradeScene, parse_variant, run_trade

    if grid not in GRIDS:
        raise ConfigError(f"grid {grid!r}: use one of {', '.join(GRIDS)}.")
    variants = dict(parse_variant(v) for v in variant) if variant else GRIDS[grid]
    scene = TradeScene(layout, site_density, scan, views, seed)
    rows = run_trade(out, scene, variants, lambda m: console.print(m, highlight=False), pictures)
    folder = scene.folder(out)
    console.print((folder / "trade.md").read_text(), highlight=False)
    console.print(f"{len(rows)} settings measured; trade.json and trade.md in {folder}")
