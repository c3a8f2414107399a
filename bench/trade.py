"""The speed/accuracy trade of the pair knobs against a truth the renderer did not draw: a 2-epoch
synthetic site run through the pipeline with the release defaults and variants of its knobs, each
variant's masks scored per pixel against the analytic ray-cast truth (siteline.trade; the same as
``siteline bench trade``).

    python bench/trade.py [--layout site|boxes|slope] [--scan flown|sampled] [--density 10] [--views 24] [--grid full|quick]
        [--variant NAME='{"radius_multiplier": 4}' ...] [--out bench-trade] [--pictures 3]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from siteline.trade import GRIDS, LAYOUTS, TradeScene, parse_variant, run_trade


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--layout", choices=LAYOUTS, default="site")
    ap.add_argument("--scan", choices=("flown", "sampled"), default="flown")
    ap.add_argument("--density", type=float, default=10.0, help="points per m2")
    ap.add_argument("--views", type=int, default=24)
    ap.add_argument("--grid", choices=tuple(GRIDS), default="full")
    ap.add_argument(
        "--variant",
        action="append",
        default=[],
        help="NAME=JSON pair knobs over the defaults (replaces --grid)",
    )
    ap.add_argument("--out", type=Path, default=Path("bench-trade"))
    ap.add_argument(
        "--pictures", type=int, default=0, help="save mask | truth | disagreement of the first N views"
    )
    args = ap.parse_args()
    variants = dict(parse_variant(v) for v in args.variant) if args.variant else GRIDS[args.grid]
    scene = TradeScene(args.layout, args.density, args.scan, args.views)
    rows = run_trade(args.out, scene, variants, pictures=args.pictures)
    print((scene.folder(args.out) / "trade.md").read_text())
    print(f"{len(rows)} settings measured")


if __name__ == "__main__":
    main()
