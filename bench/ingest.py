"""Ingest benchmark: points/s of `siteline ingest` on a LAS and a LAZ file beside a plain laspy
chunked read of the same file in the same run, and peak memory at two sizes.

    python bench/ingest.py [--points 20000000] [--small 5000000]

Each measurement runs in its own subprocess so its peak resident memory (ru_maxrss) is its own.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import laspy
import numpy as np

ORIGIN = np.array([445_000.0, 5_030_000.0, 80.0])


def make_las(path: Path, n: int, seed: int = 0, z_noise_m: float = 0.5) -> None:
    """A flat-ish site of n points over 300 m x 300 m written in chunks (memory stays bounded);
    z_noise_m spreads them vertically (0.5: a slab of clutter; 0.02: a surface)."""
    from siteline.lasio import fill_record, las_header

    rng = np.random.default_rng(seed)
    header = las_header("EPSG:32618", ORIGIN - [200, 200, 10], 0.001)
    with laspy.open(path, mode="w", header=header) as w:
        for start in range(0, n, 2_000_000):
            k = min(2_000_000, n - start)
            xyz = np.c_[rng.uniform(-150, 150, (k, 2)), rng.normal(0, z_noise_m, k)] + ORIGIN
            rec = laspy.ScaleAwarePointRecord.zeros(k, header=header)
            fill_record(
                rec,
                xyz,
                rgb=rng.integers(0, 256, (k, 3), dtype=np.uint8),
                classification=rng.choice(np.array([2, 6, 19], np.uint8), k),
                intensity=rng.integers(0, 255, k),
                gps_time=rng.uniform(0, 1000, k),
                return_number=np.ones(k, np.uint8),
            )
            w.write_points(rec)


def child(mode: str, path: str) -> None:
    t = time.perf_counter()
    if mode == "read":
        n = 0
        with laspy.open(path) as r:
            for pts in r.chunk_iterator(1_000_000):
                np.asarray(pts.x), np.asarray(pts.y), np.asarray(pts.z)
                n += len(pts)
    else:
        from siteline.catalog import migrate, open_catalog
        from siteline.catalog.engine import make_engine
        from siteline.catalog.sites import add_site
        from siteline.config import Settings, sqlite_url
        from siteline.ingest import ingest_mission
        from siteline.site import make_site_spec

        home = Path(tempfile.mkdtemp())
        settings = Settings(home, sqlite_url(home / "c.sqlite"))
        e = make_engine(settings.database_url)
        migrate.upgrade(e)
        e.dispose()
        cat = open_catalog(settings)
        with cat.transaction() as s:
            add_site(
                s,
                make_site_spec(
                    "b",
                    "EPSG:32618",
                    ORIGIN,
                    [(-120, -120), (120, -120), (120, 120), (-120, 120), (-120, -120)],
                ),
            )
        t = time.perf_counter()
        r = ingest_mission(cat, settings, Path(path).parent, "b")
        n = r.scan["point_count"]
    sec = time.perf_counter() - t
    print(
        json.dumps(
            {
                "points": n,
                "seconds": sec,
                "peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            }
        )
    )


def run(mode: str, path: Path) -> dict:
    out = subprocess.run(
        [sys.executable, __file__, "--child", mode, str(path)], capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=20_000_000)
    ap.add_argument("--small", type=int, default=5_000_000)
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(*args.child)
        return
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in (args.small, args.points):
            for ext in ("las", "laz"):
                d = Path(tmp) / f"{n}-{ext}"
                d.mkdir()
                path = d / f"cloud.{ext}"
                make_las(path, n)
                plain = run("read", path)
                ours = run("ingest", path)
                rows.append((n, ext, plain, ours))
                path.unlink()
    print("| points | format | laspy read M pts/s | ingest M pts/s | ingest / read | ingest peak MiB |")
    print("|---|---|---|---|---|---|")
    for n, ext, plain, ours in rows:
        pr, ir = plain["points"] / plain["seconds"], ours["points"] / ours["seconds"]
        print(
            f"| {n / 1e6:.0f}M | {ext.upper()} | {pr / 1e6:.2f} | {ir / 1e6:.2f} | {ir / pr:.2f} | {ours['peak_mib']:.0f} |"
        )
    peaks = {(n, ext): ours["peak_mib"] for n, ext, _, ours in rows}
    for ext in ("las", "laz"):
        print(
            f"peak memory {ext.upper()}: {args.points / 1e6:.0f}M / {args.small / 1e6:.0f}M = "
            f"{peaks[(args.points, ext)] / peaks[(args.small, ext)]:.2f}x"
        )


if __name__ == "__main__":
    main()
