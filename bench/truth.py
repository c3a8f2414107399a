"""Masks scored against a truth the renderer did not draw: a 2-epoch synthetic site (the construction
site, or the analytic box scene) run through the pipeline with the release defaults, each pair
output's masks scored per pixel against the analytic ray-cast truth (siteline.synth.viewtruth):
precision, recall and F1 of changed, boundary F (2 px), each changed object's recall, false-change
specks under 30 px per view, and the labels stage's seconds. Variants (pair knobs over the
defaults) run on the same ingested scenes in the same run.

    python bench/truth.py [--layout site|boxes] [--density 10] [--views 24]
        [--variant NAME='{"radius_multiplier": 4}' ...] [--out bench-truth] [--pictures 3]
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from PIL import Image

from siteline import pipeline
from siteline.catalog import migrate, open_catalog
from siteline.catalog.engine import make_engine
from siteline.catalog.pairs import pair_ids_of_scene
from siteline.catalog.scenes import list_scenes
from siteline.catalog.sites import add_site, get_site
from siteline.config import Settings, sqlite_url
from siteline.site.fence import load_fence_geojson
from siteline.site.spec import make_site_spec
from siteline.synth import SynthConfig, write_site
from siteline.synth.scoring import score_pair

SITE = "truth"


def _home(out: Path, cfg: SynthConfig, site_dir: Path, views: int) -> Settings:
    home = out / "home"
    settings = Settings(home=home, database_url=sqlite_url(home / "catalog.sqlite"))
    made = (home / "catalog.sqlite").exists()
    home.mkdir(parents=True, exist_ok=True)
    engine = make_engine(settings.database_url)
    migrate.upgrade(engine)
    engine.dispose()
    if made:
        return settings
    ring = load_fence_geojson(site_dir / "fence.geojson", cfg.origin)
    cat = open_catalog(settings)
    with cat.transaction() as s:
        add_site(s, make_site_spec(SITE, cfg.crs, cfg.origin, [*ring, ring[0]]), {"pair": {"views": views, "seed": 0}})
    cat.dispose()
    return settings


def _picture(out: Path, name: str, index: int, mask: np.ndarray, truth: np.ndarray) -> None:
    """mask | truth | disagreement (red: false changed, blue: missed, grey: ignored by either)."""
    colours = {0: (40, 140, 60), 1: (220, 40, 40), 255: (235, 235, 235)}

    def paint(m: np.ndarray) -> np.ndarray:
        img = np.zeros((*m.shape, 3), np.uint8)
        for v, c in colours.items():
            img[m == v] = c
        return img

    diff = np.full((*mask.shape, 3), 255, np.uint8)
    both = (mask != 255) & (truth != 255)
    diff[~both] = (200, 200, 200)
    diff[both & (mask == 1) & (truth == 0)] = (220, 30, 30)
    diff[both & (mask == 0) & (truth == 1)] = (30, 60, 220)
    diff[both & (mask == 1) & (truth == 1)] = (30, 30, 30)
    gap = np.full((mask.shape[0], 4, 3), 255, np.uint8)
    Image.fromarray(np.concatenate([paint(mask), gap, paint(truth), gap, diff], axis=1)).save(
        out / f"{name}-{index:04d}.png"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--layout", choices=("site", "boxes"), default="site")
    ap.add_argument("--density", type=float, default=10.0, help="points per m2")
    ap.add_argument("--views", type=int, default=24)
    ap.add_argument("--variant", action="append", default=[], help="NAME=JSON pair knobs over the defaults")
    ap.add_argument("--out", type=Path, default=Path("bench-truth"))
    ap.add_argument("--pictures", type=int, default=0, help="save mask | truth | disagreement of the first N views")
    args = ap.parse_args()
    out = args.out / f"{args.layout}-{args.density:g}"
    out.mkdir(parents=True, exist_ok=True)
    cfg = SynthConfig(
        epochs=2, density_pts_m2=args.density, seed=0, snow_epochs=(), projection_error_epochs=(), layout=args.layout
    )
    site_dir = out / "site"
    t0 = time.perf_counter()
    if not (site_dir / "truth" / "site.json").exists():
        write_site(site_dir, cfg)
    print(f"synthetic {args.layout} at {args.density:g} points/m2 ready ({time.perf_counter() - t0:.0f} s)")
    settings = _home(out, cfg, site_dir, args.views)
    cat = open_catalog(settings)
    doc = json.loads((site_dir / "truth" / "site.json").read_text())
    for e in doc["epochs"]:
        pipeline.ingest(cat, settings, site_dir / e["mission_dir"], SITE)
    with cat.transaction() as s:
        scenes = list_scenes(s, get_site(s, SITE))
        pid = pair_ids_of_scene(s, scenes[-1].id)[0]
    base = pipeline.release_parameters(cat, SITE).pair
    variants = {"default": {}} | {v.split("=", 1)[0]: json.loads(v.split("=", 1)[1]) for v in args.variant}
    rows = []
    for name, knobs in variants.items():
        params = replace(base, **knobs)
        t = time.perf_counter()
        result = pipeline.process_pairs(cat, settings, [pid], params)[pid]
        seconds = time.perf_counter() - t
        kept = []

        def keep(view, mask, truth, name=name, kept=kept):  # noqa: ANN001, ANN202
            if len(kept) < args.pictures:
                _picture(out, name, view.index, mask, truth.mask)
                kept.append(view.index)

        score = score_pair(settings.store, result.root, site_dir, (0, 1), keep)
        row = {"variant": name, "knobs": knobs, "seconds": seconds, "label_seconds": result.labels.seconds or float("nan"),
               "radius_m": result.radius_m} | score.to_dict()  # fmt: skip
        rows.append(row)
        objects = ", ".join(f"{k} {v:.2f}" for k, v in row["object_recall"].items())
        print(
            f"{name:>12}: P {row['precision']:.3f} R {row['recall']:.3f} F1 {row['f1']:.3f} "
            f"boundary F {row['boundary_f']:.3f} specks/view median {row['specks_median']:.0f} "
            f"(max {row['specks_max']}), rim pieces/view median {row['rims_median']:.0f}, scored {row['scored_share']:.1%} of pixels, labels {row['label_seconds']:.1f} s, "
            f"pair {seconds:.0f} s; {objects}"
        )
    cat.dispose()
    (out / "scores.json").write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
