"""View-generation benchmark on a real cloud (tests/data/real/autzen_trim.laz, 110k points, 1.9 points/m2,
cameras planned from the cloud): seconds, candidates, probe reads and points read per candidate batch,
at the cloud's density and at 4x (jittered copies), beside the previous way (a read and a full z-buffer
render per probe) measured in the same run.

    python bench/views.py [--dense 4]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import laspy
import numpy as np

REAL = Path(__file__).resolve().parents[1] / "tests" / "data" / "real" / "autzen_trim.laz"


def _epochs(out: Path, copies: int) -> tuple[Path, Path]:
    """Two epochs of autzen at ``copies`` x its density: the second with a block removed."""
    las = laspy.read(REAL)
    rng = np.random.default_rng(0)
    xyz = np.c_[las.x, las.y, las.z]
    pts = las.points
    if copies > 1:
        idx = np.tile(np.arange(len(xyz)), copies)
        pts = las.points[idx]
        xyz = xyz[idx] + np.r_[np.zeros((len(las.points), 3)), rng.normal(0, 0.8, (len(idx) - len(las.points), 3))]
    paths = []
    for k in range(2):
        keep = np.ones(len(xyz), bool)
        if k:
            c = xyz[:, :2].mean(axis=0)
            keep = ~((np.abs(xyz[:, 0] - c[0]) < 60) & (np.abs(xyz[:, 1] - c[1]) < 60))
        new = laspy.LasData(las.header)
        new.points = pts[keep]
        new.x, new.y, new.z = xyz[keep, 0], xyz[keep, 1], xyz[keep, 2]
        new.update_header()
        paths.append(out / f"e{k}.laz")
        new.write(paths[-1])
    return paths[0], paths[1]


def _views(home: Path, copies: int, old_way: bool) -> dict[str, float]:
    from datetime import UTC, datetime

    from siteline import pipeline
    from siteline.catalog import migrate, open_catalog
    from siteline.catalog.engine import make_engine
    from siteline.catalog.sites import add_site
    from siteline.config import Settings, sqlite_url
    from siteline.ingest import IngestOptions
    from siteline.labelsets.store import open_labelled
    from siteline.pairs import PairParams, sources
    from siteline.pairs import execute as pair_execute
    from siteline.pairs.plan import plan_pair
    from siteline.progress import no_progress
    from siteline.render.zbuffer import render_points
    from siteline.site import make_site_spec
    from siteline.views import generate

    settings = Settings(home=home, database_url=sqlite_url(home / "catalog.sqlite"))
    engine = make_engine(settings.database_url)
    migrate.upgrade(engine)
    engine.dispose()
    cat = open_catalog(settings)
    with cat.transaction() as s:
        add_site(s, make_site_spec("autzen", "EPSG:32610", (493000.0, 4878000.0, 130.0), None))
    for k, path in enumerate(_epochs(home, copies)):
        opts = IngestOptions(captured_at=datetime(2020, 5, 1 + 10 * k, tzinfo=UTC))
        pipeline.ingest(cat, settings, path, "autzen", opts, workers=2)
    points = laspy.open(home / "e1.laz").header.point_count
    params = PairParams(scale=0.1, point_size_px=5, views=300)
    with cat.transaction() as s:
        plan = plan_pair(s, settings.store, 1, params)
    t2 = open_labelled(plan.t2.tiles, plan.t2.label_set)
    made: list[sources.TilePointSource] = []

    class Recorded(sources.TilePointSource):
        def __init__(self, *a, **k) -> None:  # noqa: ANN002, ANN003
            super().__init__(*a, **k)
            made.append(self)

        def prefetch(self, cameras, scale) -> None:  # noqa: ANN001
            if not old_way:
                super().prefetch(cameras, scale)

    real_coverage = generate.coverage_of
    pair_execute.TilePointSource = Recorded  # type: ignore[misc]
    if old_way:
        generate.coverage_of = lambda xyz, cam, st: render_points(xyz, cam, st).coverage  # type: ignore[assignment]
    try:
        t0 = time.perf_counter()
        views = pair_execute.pair_views(plan, t2, no_progress)
        seconds = time.perf_counter() - t0
    finally:
        pair_execute.TilePointSource = sources.TilePointSource  # type: ignore[misc]
        generate.coverage_of = real_coverage
    cat.dispose()
    src = made[0]
    batches = len(plan.cameras)
    return {
        "points": points, "views": len(views.views), "candidates": views.candidates, "seconds": seconds,
        "reads": src.reads, "points_read": src.points_read, "read_per_batch": src.points_read / batches / points,
    }  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--dense", type=int, default=4, help="copies of each point in the dense run")
    args = ap.parse_args()
    rows = []
    for copies, old in ((1, True), (1, False), (args.dense, False)):
        with tempfile.TemporaryDirectory() as d:
            r = _views(Path(d), copies, old)
        rows.append((copies, old, r))
        print(
            f"{'previous' if old else 'batched'} x{copies}: {r['points']:,} points, {r['candidates']} candidates -> "
            f"{r['views']} views in {r['seconds']:.1f} s ({1000 * r['seconds'] / r['candidates']:.1f} ms a candidate), "
            f"{r['reads']} probe reads, {r['points_read'] / 1e6:.1f}M points read "
            f"({r['read_per_batch']:.2f} x the cloud per candidate batch)",
            flush=True,
        )
    base, new, dense = (r for _, _, r in rows)
    print(f"batched / previous at x1: time {new['seconds'] / base['seconds']:.2f}x, points read "
          f"{new['points_read'] / base['points_read']:.2f}x")
    print(f"x{args.dense} / x1 density (batched): time {dense['seconds'] / new['seconds']:.2f}x, points read "
          f"{dense['points_read'] / new['points_read']:.2f}x, cloud {dense['points'] / new['points']:.2f}x")


if __name__ == "__main__":
    main()
