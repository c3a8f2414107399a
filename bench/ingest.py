"""Ingest benchmark: `siteline ingest` (ingest + tile) of LAS and LAZ files of the same 100 m x 100 m
site at two densities, against a plain laspy read and a lazrs decode of the same file in the same run.

    python bench/ingest.py [--small 4000000] [--large 40000000] [--workers 2] [--batch-points N]
    python bench/ingest.py --scene 200000000 [--scene-area-m2 32300] --formats las   # one paper scene

Per file: M points/s of ingest + tile and of the tile stage alone (which takes the partition into
tile runs that ingest's scan kept, siteline.pointpass.partition), per core, as a ratio of the plain
read (LAS) and of the lazrs decode (LAZ, laspy's parallel lazrs backend); peak resident memory; bytes
per point of the tile store against the LAZ file; node index rows and points per node. Each
measurement runs in its own subprocess so its peak memory (ru_maxrss) is its own; the last lines are
the growth from the small to the large density (memory should stay flat, nodes grow with points).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path

import laspy
import numpy as np

from siteline.catalog.context import StageContext
from siteline.config import DEFAULT_TILE_BATCH_POINTS
from siteline.pointpass import TilingResources

ORIGIN = np.array([445_000.0, 5_030_000.0, 80.0])
HALF_M = 50.0  # the site: 100 m x 100 m, i.e. 4 tiles of 50 m


def make_las(path: Path, n: int, seed: int = 0, z_noise_m: float = 0.05, half_m: float = HALF_M) -> None:
    """n points over a (2 half_m)^2 site, written in chunks (memory stays bounded), in flight-line
    order (sorted by GPS time along y strips, as a scanner writes them); z_noise_m spreads them
    vertically about a gentle surface."""
    from siteline.pointpass import fill_record, las_header

    rng = np.random.default_rng(seed)
    header = las_header("EPSG:32618", ORIGIN - [half_m + 10, half_m + 10, 10], 0.001)
    step = 2_000_000
    with laspy.open(path, mode="w", header=header) as w:
        for start in range(0, n, step):
            k = min(step, n - start)
            # a strip of the site per chunk: the scanner sweeps it in time order
            y0 = -half_m + 2 * half_m * start / n
            y1 = -half_m + 2 * half_m * (start + k) / n
            xy = np.c_[rng.uniform(-half_m, half_m, k), np.sort(rng.uniform(y0, y1, k))]
            z = 0.02 * xy[:, 0] + 0.5 * np.sin(xy[:, 1] / 7.0) + rng.normal(0, z_noise_m, k)
            rec = laspy.ScaleAwarePointRecord.zeros(k, header=header)
            fill_record(
                rec,
                np.c_[xy, z] + ORIGIN,
                dict(
                    rgb=rng.integers(0, 256, (k, 3), dtype=np.uint8),
                    classification=rng.choice(np.array([2, 6, 19], np.uint8), k),
                    intensity=rng.integers(0, 255, k),
                    # a scanner's clock counts whole microseconds: each time the float64 nearest one
                    # (400000 + k 2e-6 summed in floating point is one ulp off for some k past 22.5M,
                    # and such times round-trip at no decimal scale, so they cost 4.6 bytes a point)
                    gps_time=(400_000_000_000 + 2 * (start + np.arange(k))) / 1e6,
                    return_number=np.ones(k, np.uint8),
                ),
            )
            w.write_points(rec)


def _vm_hwm_mib(pid: int | str) -> float:
    with open(f"/proc/{pid}/status") as fh:
        return next(int(line.split()[1]) for line in fh if line.startswith("VmHWM")) / 1024


def _children() -> list[int]:
    """This process's child processes (its pool's workers), read from /proc: the same in any tree."""
    tasks = Path(f"/proc/{os.getpid()}/task")
    return [int(pid) for t in tasks.iterdir() for pid in (t / "children").read_text().split()]


def child(mode: str, path: str, workers: int, batch_points: int, half_m: float) -> None:
    t = time.perf_counter()
    out: dict = {}
    if mode == "read":  # plain laspy: LAS read, or LAZ decode with the parallel lazrs backend
        n = 0
        backend = laspy.LazBackend.LazrsParallel
        with laspy.open(path, laz_backend=backend) as r:
            for pts in r.chunk_iterator(1_000_000):
                np.asarray(pts.x), np.asarray(pts.y), np.asarray(pts.z)
                n += len(pts)
    else:
        from siteline.catalog import migrate, open_catalog
        from siteline.catalog.engine import make_engine
        from siteline.catalog.sites import add_site
        from siteline.config import Settings, sqlite_url
        from siteline.ingest.options import IngestOptions
        from siteline.ingest.stage import ingest_mission

        try:
            from siteline.site.spec import make_site_spec
        except ImportError:  # --tree: a checkout from before the site package (siteline.site was a module)
            from siteline.site import make_site_spec  # type: ignore[attr-defined,no-redef]
        from siteline.tiles.stage import tile_scene

        home = Path(tempfile.mkdtemp())
        settings = Settings(home, sqlite_url(home / "c.sqlite"), tile_batch_points=batch_points)
        e = make_engine(settings.database_url)
        migrate.upgrade(e)
        e.dispose()
        cat = open_catalog(settings)
        h = half_m + 5
        with cat.transaction() as s:
            add_site(
                s, make_site_spec("b", "EPSG:32618", ORIGIN, [(-h, -h), (h, -h), (h, h), (-h, h), (-h, -h)])
            )
        t = time.perf_counter()
        # a generated LAS's GPS times are seconds of an unnamed week: its capture time is given
        opts = IngestOptions(captured_at=datetime(2026, 1, 1, tzinfo=UTC))
        r = ingest_mission(StageContext(cat, settings), Path(path).parent, "b", opts)
        t_ingest = time.perf_counter() - t
        tiling = tile_scene(
            StageContext(cat, settings), r.scene_id, resources=TilingResources(workers=workers)
        ).tiling
        assert tiling is not None
        n = tiling.points
        out = {
            "ingest_s": t_ingest,
            "tile_s": tiling.seconds,
            "bytes_per_point": tiling.bytes_per_point,
            "nodes": tiling.nodes,
            "tiles": tiling.tiles,
            "checksum": tiling.checksum,
        }
        cat.dispose()
        shutil.rmtree(home, ignore_errors=True)  # the stored copy, tiles and catalog of the run
    sec = time.perf_counter() - t
    # each process's own peak (VmHWM): ru_maxrss would count the parent's size at the fork (the pool
    # shuts down as the process exits)
    kids = max((_vm_hwm_mib(pid) for pid in _children()), default=0.0)
    peak = _vm_hwm_mib("self")
    print(json.dumps({"points": n, "seconds": sec, "peak_mib": peak, "worker_peak_mib": kids, **out}))


def run(
    mode: str, path: Path, workers: int, batch_points: int, half_m: float, tree: str | None = None
) -> dict:
    """One measurement in its own process; ``tree``: a siteline checkout whose library it runs."""
    env = os.environ | ({"PYTHONPATH": str(Path(tree) / "platform")} if tree else {})
    out = subprocess.run(
        [sys.executable, __file__, "--child", mode, str(path), str(workers), str(batch_points), str(half_m)],
        capture_output=True,
        text=True,
        env=env,
    )
    if out.returncode:
        raise SystemExit(f"{mode} of {path} failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--small", type=int, default=4_000_000)
    ap.add_argument("--large", type=int, default=40_000_000)
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument(
        "--batch-points", type=int, default=DEFAULT_TILE_BATCH_POINTS, help="SITELINE_TILE_BATCH_POINTS"
    )
    ap.add_argument("--scene", type=int, default=0, help="one scene of this many points instead")
    ap.add_argument("--scene-area-m2", type=float, default=32_300.0)
    ap.add_argument("--formats", default="laz,las")
    ap.add_argument(
        "--tree", action="append", default=[],
        help="NAME=DIR: also ingest each file with the siteline library of checkout DIR (e.g. before a refactor); "
        "prints each tree's speed against this one's and whether their tile-store checksums agree",
    )  # fmt: skip
    ap.add_argument("--child", nargs=5, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.child[0], args.child[1], int(args.child[2]), int(args.child[3]), float(args.child[4]))
        return
    cores = args.workers
    rows, others = [], []
    cases = (
        [(args.scene, args.scene_area_m2**0.5 / 2)]
        if args.scene
        else [(args.small, HALF_M), (args.large, HALF_M)]
    )
    with tempfile.TemporaryDirectory() as tmp:
        for n, half_m in cases:
            laz_bpp = 0.0
            for ext in args.formats.split(","):
                d = Path(tmp) / f"{n}-{ext}"
                d.mkdir()
                path = d / f"cloud.{ext}"
                make_las(path, n, half_m=half_m)
                if ext == "laz":
                    laz_bpp = path.stat().st_size / n
                plain = run("read", path, cores, args.batch_points, half_m)
                for name, tree in [tuple(s.split("=", 1)) for s in args.tree]:
                    others.append((n, ext, name, run("ingest", path, cores, args.batch_points, half_m, tree)))
                ours = run("ingest", path, cores, args.batch_points, half_m)
                rows.append((n, half_m, ext, plain, ours, laz_bpp))
                path.unlink()
    print(
        f"site {2 * cases[0][1]:.0f} m square; {cores} worker processes on {os.cpu_count()} cores; "
        f"tiles over {args.batch_points:,} points written in batches"
    )
    print(
        "| points | pts/m2 | format | baseline M pts/s | ingest+tile M pts/s (per core) | tile only M pts/s (per core) "
        "| x baseline | peak MiB (main / worker) | store B/pt | LAZ B/pt | nodes | pts/node |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for n, half_m, ext, plain, ours, laz_bpp in rows:
        base = plain["points"] / plain["seconds"]
        total = ours["points"] / (ours["ingest_s"] + ours["tile_s"])
        tile = ours["points"] / ours["tile_s"]
        label = "LAS (laspy read)" if ext == "las" else "LAZ (lazrs decode)"
        print(
            f"| {n / 1e6:.0f}M | {n / (2 * half_m) ** 2:,.0f} | {label} | {base / 1e6:.2f} | "
            f"{total / 1e6:.2f} ({total / cores / 1e6:.2f}) | {tile / 1e6:.2f} ({tile / cores / 1e6:.2f}) | "
            f"{total / base:.2f} | {ours['peak_mib']:.0f} / {ours['worker_peak_mib']:.0f} | "
            f"{ours['bytes_per_point']:.1f} | {laz_bpp or float('nan'):.1f} | {ours['nodes']:,} | "
            f"{n / max(ours['nodes'], 1):,.0f} |"
        )
        print(f"  ingest {ours['ingest_s']:.1f} s, tile {ours['tile_s']:.1f} s")
    for ext in args.formats.split(",") if not args.scene else ():
        small = next(o for n, _, e, _, o, _ in rows if n == args.small and e == ext)
        large = next(o for n, _, e, _, o, _ in rows if n == args.large and e == ext)
        peak = max(large["peak_mib"], large["worker_peak_mib"]) / max(
            small["peak_mib"], small["worker_peak_mib"]
        )
        print(
            f"{ext.upper()} {args.large / args.small:.0f}x the density: peak memory {peak:.2f}x, "
            f"nodes {large['nodes'] / small['nodes']:.2f}x"
        )

    for n, ext, name, other in others:
        ours = next(o for m, _, e, _, o, _ in rows if m == n and e == ext)
        mine, theirs = ours["ingest_s"] + ours["tile_s"], other["ingest_s"] + other["tile_s"]
        same = "equal" if ours["checksum"] == other["checksum"] else "DIFFER"
        print(
            f"{n / 1e6:.1f}M {ext.upper()}: this tree ingest+tile {mine:.1f} s, {name} {theirs:.1f} s "
            f"({mine / theirs:.2f}x); tile-store checksums {same} ({ours['checksum'][:16]})"
        )


if __name__ == "__main__":
    main()
