"""``siteline demo``: the whole pipeline on the embedded default (SQLite, local files, a generated site):
synthetic missions -> ingest and tiles -> pairs -> release build and publish -> a short evaluation."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import typer

from siteline.catalog import Catalog, open_catalog, store_roots
from siteline.catalog.context import StageContext
from siteline.catalog.engine import make_engine
from siteline.catalog.releases import get_release, list_releases
from siteline.catalog.sites import add_site, get_site, scene_count, site_record
from siteline.cli.common import console, print_record, print_table, settings
from siteline.config import Settings
from siteline.errors import SiteNotFoundError
from siteline.records.params.release import ReleaseKnobs
from siteline.records.release import ReleaseOptions
from siteline.site.fence import load_fence_geojson
from siteline.site.spec import make_site_spec

DEMO_SITE = "demo"
DEMO_RELEASE = "demo-cd"
# the demo site's release settings: 24 views a pair; scale and point size stay auto (the synthetic
# photos are 660 x 495, 1/8 of the L2 sensor: renders of a 512 px long side, points sized to the density)
DEMO_SETTINGS = ReleaseKnobs(pair={"views": 24, "seed": 0})


def _catalog_at_head(cfg: Settings) -> None:
    """Create the home and bring its catalog to the newest revision."""
    from siteline.catalog import migrate  # alembic: only for commands that migrate

    cfg.home.mkdir(parents=True, exist_ok=True)
    engine = make_engine(cfg.database_url)
    migrate.upgrade(engine, roots=store_roots(cfg))
    engine.dispose()
    console.rule("1. catalog")
    console.print(f"home {cfg.home}; catalog at revision {migrate.head_revision()}")


def _site(
    cat: Catalog, site_name: str, synth_dir: Path, origin: tuple[float, float, float], crs: str
) -> None:
    with cat.transaction() as s:
        try:
            site = get_site(s, site_name)
            console.print(f"site {site_name} exists: reusing it")
        except SiteNotFoundError:
            ring = load_fence_geojson(synth_dir / "fence.geojson", origin)
            site = add_site(s, make_site_spec(site_name, crs, origin, [*ring, ring[0]]), DEMO_SETTINGS)
        record = site_record(site, scene_count(s, site))
    keep = ("name", "crs", "origin", "fence_area_m2", "taxonomy", "release_settings")
    print_record(f"site {site_name}", {k: record[k] for k in keep})


def _release(cat: Catalog, cfg: Settings, site_name: str) -> tuple[Path, str]:
    """The demo release: the published one when there is one, else built and published now."""
    from siteline import pipeline

    with cat.transaction() as s:
        published = [r for r in list_releases(s, DEMO_RELEASE) if r.status == "published"]
        if published:
            console.print(f"release {DEMO_RELEASE} {published[-1].version} already published: reusing it")
            return Path(str(published[-1].root_uri)), published[-1].version
    pub = pipeline.release(
        StageContext(cat, cfg), site_name, DEMO_RELEASE, options=ReleaseOptions(publish=True)
    )
    console.print(f"release {DEMO_RELEASE} {pub.version}: {pub.reason}")
    return Path(pub.root), pub.version


def _baseline(cfg: Settings, root: Path, version: str, stats: dict, train_iters: int) -> None:
    from siteline.baseline import TrainParams, evaluate, train

    out = cfg.home / "baseline" / f"{DEMO_RELEASE}-{version}"
    log = train(root, out, TrainParams(max_iters=train_iters, crop=128))
    split = "test" if stats["class_balance"].get("test") else "train"
    result = evaluate(root, out / "model.pt", out / f"results-{split}.json", split)
    losses = log["losses"]
    k = max(1, min(10, len(losses) // 4))  # single batches are noisy: the first and last k, averaged
    trivial = result["trivial_scores"]["miou"]
    console.print(
        f"trained {log['iterations']} iterations in {log['seconds']:.0f} s (mean loss of the first {k} "
        f"{np.mean(losses[:k]):.3f} -> the last {k} {np.mean(losses[-k:]):.3f}); {split} mIoU "
        f"{result['scores']['miou']:.3f} against {trivial:.3f} for predicting every pixel unchanged, F1 changed "
        f"{result['scores']['f1']:.3f} -> {out / f'results-{split}.json'}",
    )


def demo(
    site_name: str = typer.Option(DEMO_SITE, "--site", help="Name of the demo site."),
    epochs: int = typer.Option(4, "--epochs", help="Synthetic epochs."),
    train_iters: int = typer.Option(
        150,
        "--train-iters",
        help="Baseline training iterations (150: enough to clear the all-unchanged floor).",
    ),
) -> None:
    """Run the whole pipeline on a generated site and print where the release is and its statistics."""
    from siteline import pipeline
    from siteline.synth import SynthParams, write_site

    t_start = time.perf_counter()
    cfg = settings()
    _catalog_at_head(cfg)
    console.rule("2. synthetic site")
    synth_dir, synth = cfg.home / "synthetic-site", SynthParams(epochs=epochs)
    if not (synth_dir / "truth" / "site.json").exists():
        write_site(synth_dir, synth, progress=lambda name: console.print(f"  generated epoch {name}"))
    epochs_doc = json.loads((synth_dir / "truth" / "site.json").read_text())["epochs"]
    cat = open_catalog(cfg)
    try:
        _site(cat, site_name, synth_dir, synth.origin, synth.crs)
        console.rule("3. ingest and tile")
        for e in epochs_doc:
            done = pipeline.ingest(StageContext(cat, cfg), synth_dir / e["mission_dir"], site_name)
            console.print(f"  {done.ingest.message}")
        console.rule("4. release")
        root, version = _release(cat, cfg, site_name)
        stats = json.loads((root / "stats.json").read_text())
        print_table(
            f"release {DEMO_RELEASE} {version} at {root}", ["split", "images", "changed", "unchanged", "ignore"],
            [[k, v["images"], v["changed"], v["unchanged"], v["ignore"]] for k, v in stats["class_balance"].items()],
        )  # fmt: skip
        with cat.transaction() as s:
            manifest_sha = get_release(s, DEMO_RELEASE, version).manifest_sha256
        console.print(f"manifest sha256 {manifest_sha}; datasheet {root / 'README.md'}")
    finally:
        cat.dispose()
    console.rule("5. baseline (FC-Siam-diff, a short run)")
    _baseline(cfg, root, version, stats, train_iters)
    console.rule(f"done in {time.perf_counter() - t_start:.0f} s")
