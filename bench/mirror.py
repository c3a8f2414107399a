#!/usr/bin/env python3
"""Mirrored views under both mirror rules: how much of each view is valid (non-ignore) and how much
of it changed, mirrored against unmirrored views of the same pair (issue: views that look into the
site). Prints medians; one synthetic 2-epoch site, one run.

    python bench/mirror.py [--density 10] [--views 300]
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--density", type=float, default=10.0, help="points per m2")
    ap.add_argument("--views", type=int, default=300)
    args = ap.parse_args()

    from siteline import pipeline
    from siteline.catalog import migrate, open_catalog
    from siteline.catalog.context import StageContext
    from siteline.catalog.engine import make_engine
    from siteline.catalog.sites import add_site
    from siteline.config import Settings, sqlite_url
    from siteline.records.params.pairs import PairParams
    from siteline.site.fence import load_fence_geojson
    from siteline.site.spec import make_site_spec
    from siteline.synth import SynthParams, write_site

    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        cfg = SynthParams(epochs=2, density_pts_m2=args.density, seed=0)
        write_site(root / "site", cfg)
        settings = Settings(home=root / "home", database_url=sqlite_url(root / "home" / "catalog.sqlite"))
        engine = make_engine(settings.database_url)
        migrate.upgrade(engine)
        engine.dispose()
        cat = open_catalog(settings)
        ring = load_fence_geojson(root / "site" / "fence.geojson", cfg.origin)
        with cat.transaction() as s:
            add_site(s, make_site_spec("mirror", cfg.crs, cfg.origin, [*ring, ring[0]]))
        truth = json.loads((root / "site" / "truth" / "site.json").read_text())
        for e in truth["epochs"]:
            pipeline.ingest(
                StageContext(cat, settings), root / "site" / e["mission_dir"], "mirror", workers=1
            )
        print(
            f"site: 2 epochs at {args.density:g} points/m2, {args.views} views per rule, scale 1/8 of 660 x 495"
        )
        print("| rule | views | mirrored median valid | unmirrored median valid | mirrored median change | "
              "unmirrored median change | s |")  # fmt: skip
        print("|---|---|---|---|---|---|---|")
        for rule in ("reflect", "aim-site"):
            params = PairParams(views=args.views, view_params={"mirror_rule": rule})
            t0 = time.perf_counter()
            out = pipeline.process_pairs(StageContext(cat, settings), [1], params)[1]
            sec = time.perf_counter() - t0
            mir = [v for v in out.views if "-mirror-" in v["strategy"]]
            orig = [v for v in out.views if "-orig-" in v["strategy"]]

            def med(vs: list[dict], key: str) -> str:
                return f"{statistics.median(v[key] for v in vs):.3f}" if vs else "-"

            print(f"| {rule} | {len(mir)} mirrored / {len(orig)} | {med(mir, 'valid')} | {med(orig, 'valid')} | "
                  f"{med(mir, 'change_ratio')} | {med(orig, 'change_ratio')} | {sec:.0f} |")  # fmt: skip
        cat.dispose()


if __name__ == "__main__":
    main()
