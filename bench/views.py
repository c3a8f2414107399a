"""View-generation benchmark on a real cloud (tests/data/real/autzen_trim.laz, 110k points, 1.9 points/m2,
cameras planned from the cloud): seconds (and per 100k points), candidates, candidates probed, reads and
points read (against the cloud's points), at the cloud's density and at 4x (jittered copies); and the
spread of pitch and height of the views drawn under the release defaults (world splats, min_valid 0.7)
beside the rules releases used before (fixed disks, min_valid 0.25), measured in the same run.

    python bench/views.py [--dense 4] [--views 300]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import laspy
import numpy as np

from siteline.catalog.context import StageContext

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
        xyz = (
            xyz[idx]
            + np.r_[np.zeros((len(las.points), 3)), rng.normal(0, 0.8, (len(idx) - len(las.points), 3))]
        )
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


def spread(views: list, ground: object) -> dict[str, float]:
    """Pitch (degrees below the horizon of the optical axis) and height above the ground plane (m) of
    ``views``: 10th, 50th and 90th percentiles and standard deviation."""
    pitch = np.array([np.degrees(np.arcsin(-v.camera.R[2, 2])) for v in views])
    height = ground.height(np.array([v.camera.center for v in views])) if views else np.zeros(0)  # type: ignore[attr-defined]
    out = {}
    for name, vals in (("pitch_deg", pitch), ("height_m", height)):
        p10, p50, p90 = np.percentile(vals, [10, 50, 90]) if len(vals) else (0.0, 0.0, 0.0)
        out |= {
            f"{name}_p10": p10,
            f"{name}_p50": p50,
            f"{name}_p90": p90,
            f"{name}_std": float(np.std(vals)),
        }
    return out


def _views(home: Path, copies: int, rules: dict, views: int) -> dict[str, float]:
    from datetime import UTC, datetime

    from siteline import pipeline
    from siteline.catalog import migrate, open_catalog
    from siteline.catalog.engine import make_engine
    from siteline.catalog.sites import add_site
    from siteline.config import Settings, sqlite_url
    from siteline.ingest.options import IngestOptions
    from siteline.labelsets.store import open_labelled
    from siteline.pairs import execute as pair_execute
    from siteline.pairs import sources
    from siteline.pairs.plan import plan_pair
    from siteline.progress import no_progress
    from siteline.records.params.pairs import PairParams
    from siteline.site.spec import make_site_spec

    settings = Settings(home=home, database_url=sqlite_url(home / "catalog.sqlite"))
    if not (home / "catalog.sqlite").exists():
        engine = make_engine(settings.database_url)
        migrate.upgrade(engine)
        engine.dispose()
        cat = open_catalog(settings)
        with cat.transaction() as s:
            add_site(s, make_site_spec("autzen", "EPSG:32610", (493000.0, 4878000.0, 130.0), None))
        for k, path in enumerate(_epochs(home, copies)):
            opts = IngestOptions(captured_at=datetime(2020, 5, 1 + 10 * k, tzinfo=UTC))
            pipeline.ingest(StageContext(cat, settings), path, "autzen", opts, workers=2)
    else:
        cat = open_catalog(settings)
    points = laspy.open(home / "e1.laz").header.point_count
    params = PairParams(scale=0.1, point_size_px=5, views=views, **rules)
    with cat.transaction() as s:
        plan = plan_pair(s, settings.store, 1, params)
    t1, t2 = (open_labelled(sc.tiles, sc.label_set) for sc in (plan.t1, plan.t2))
    made: list[sources.TilePointSource] = []

    class Recorded(sources.TilePointSource):
        def __init__(self, *a, **k) -> None:  # noqa: ANN002, ANN003
            super().__init__(*a, **k)
            made.append(self)

    pair_execute.TilePointSource = Recorded  # type: ignore[misc]
    try:
        t0 = time.perf_counter()
        drawn = pair_execute.pair_views(plan, t1, t2, no_progress)
        seconds = time.perf_counter() - t0
    finally:
        pair_execute.TilePointSource = sources.TilePointSource  # type: ignore[misc]
    cat.dispose()
    src = made[0]
    return {
        "points": points, "views": len(drawn.views), "candidates": drawn.candidates, "probed": drawn.probed,
        "seconds": seconds, "reads": src.reads, "points_read": src.points_read, "in_memory": src.in_memory,
        **spread(drawn.views, drawn.ground),
    }  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--dense", type=int, default=4, help="copies of each point in the dense run")
    ap.add_argument("--views", type=int, default=300, help="views asked per pair")
    args = ap.parse_args()
    now = {}  # the release defaults
    before = {"splat": "fixed", "fill_px": 0, "min_valid": 0.25}  # the rules releases used before
    rows = {}
    with tempfile.TemporaryDirectory() as d1, tempfile.TemporaryDirectory() as d4:
        for copies, home in ((1, Path(d1)), (args.dense, Path(d4))):
            for name, rules in (("defaults", now), ("before", before)):
                if copies > 1 and name == "before":
                    continue
                r = rows[(copies, name)] = _views(home, copies, rules, args.views)
                print(
                    f"x{copies} {name}: {r['points']:,} points, {r['candidates']} candidates, {r['probed']} probed -> "
                    f"{r['views']} views in {r['seconds']:.1f} s ({100_000 * r['seconds'] / r['points']:.2f} s per "
                    f"100k points), {r['reads']} reads, {r['points_read']:,} points read "
                    f"({r['points_read'] / r['points']:.2f} x the cloud{', held in memory' if r['in_memory'] else ''}); "
                    f"pitch p10/p50/p90 {r['pitch_deg_p10']:.0f}/{r['pitch_deg_p50']:.0f}/{r['pitch_deg_p90']:.0f} deg "
                    f"(sd {r['pitch_deg_std']:.1f}), height {r['height_m_p10']:.0f}/{r['height_m_p50']:.0f}/"
                    f"{r['height_m_p90']:.0f} m (sd {r['height_m_std']:.1f})",
                    flush=True,
                )
    x1, x4 = rows[(1, "defaults")], rows[(args.dense, "defaults")]
    print(
        f"x{args.dense} / x1 density: time {x4['seconds'] / x1['seconds']:.2f}x, points read "
        f"{x4['points_read'] / x1['points_read']:.2f}x, cloud {x4['points'] / x1['points']:.2f}x"
    )


if __name__ == "__main__":
    main()
