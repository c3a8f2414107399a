"""Tile store benchmark: LAS -> tiles throughput beside a plain laspy read of the same file (same run),
bytes per point, peak memory at two sizes, a codec comparison, and for a 1/8-scale view of a dense
scene the points read per covered pixel and the batched read throughput.

    python -m bench.tiles [--points 20000000] [--small 5000000] [--view-only]
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

import numpy as np

from bench.ingest import ORIGIN, make_las  # the same generated site as bench/ingest.py
from siteline.pointpass import TilingResources
from siteline.tiles.writer import TileInput


def child(mode: str, path: str, out: str) -> None:
    import laspy
    import pyproj

    from siteline.site.spec import make_site_spec
    from siteline.tiles.writer import write_tiles

    t = time.perf_counter()
    if mode == "read":
        n = 0
        with laspy.open(path) as r:
            for pts in r.chunk_iterator(1_000_000):
                np.asarray(pts.x), np.asarray(pts.y), np.asarray(pts.z), np.asarray(pts.classification)
                n += len(pts)
        extra = {}
    else:
        site = make_site_spec("b", "EPSG:32618", ORIGIN)
        r = write_tiles(
            TileInput(Path(path), site, pyproj.CRS("EPSG:32618")),
            Path(out),
            resources=TilingResources(workers=2),
        )
        n, extra = r.points, {"bytes_per_point": r.bytes_per_point, "tiles": r.tiles, "levels": r.levels}
    sec = time.perf_counter() - t
    print(
        json.dumps(
            {
                "points": n,
                "seconds": sec,
                "peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                **extra,
            }
        )
    )


def run(*args: str) -> dict:
    out = subprocess.run(
        [sys.executable, "-m", "bench.tiles", "--child", *args],
        capture_output=True,
        text=True,
        cwd=Path(__file__).resolve().parents[1],
    )
    if out.returncode:
        raise SystemExit(out.stderr)
    return json.loads(out.stdout.strip().splitlines()[-1])


def codecs(n: int = 2_000_000) -> None:
    import zarr
    from zarr.codecs import BloscCodec, BloscShuffle, ZstdCodec

    rng = np.random.default_rng(0)
    xyz = np.c_[rng.integers(0, 50_000, (n, 2)), rng.normal(0, 500, n)].astype(np.int32)
    xyz = xyz[np.lexsort((xyz[:, 1], xyz[:, 0]))]  # spatially sorted, as levels make them
    options = {
        "none": None,
        "zstd-3": ZstdCodec(level=3),
        "blosc-zstd-3-shuffle": BloscCodec(cname="zstd", clevel=3, shuffle=BloscShuffle.shuffle),
        "blosc-zstd-5-shuffle": BloscCodec(cname="zstd", clevel=5, shuffle=BloscShuffle.shuffle),
        "blosc-lz4-5-shuffle": BloscCodec(cname="lz4", clevel=5, shuffle=BloscShuffle.shuffle),
    }
    print("| codec (xyz int32, 2M points) | write M pts/s | read M pts/s | bytes/point |")
    print("|---|---|---|---|")
    for name, codec in options.items():
        with tempfile.TemporaryDirectory() as d:
            a = zarr.create_array(
                f"{d}/a",
                shape=xyz.shape,
                dtype="int32",
                chunks=(65536, 3),
                shards=(1048576, 3),
                compressors=codec,
                fill_value=0,
            )
            t = time.perf_counter()
            a[...] = xyz
            w = time.perf_counter() - t
            t = time.perf_counter()
            a[...]
            r = time.perf_counter() - t
            size = sum(p.stat().st_size for p in Path(d).rglob("*") if p.is_file())
        print(f"| {name} | {n / w / 1e6:.1f} | {n / r / 1e6:.1f} | {size / n:.2f} |")


def view_read(points: int) -> None:
    """1/8-scale nadir view over a dense scene: points read per covered pixel and coverage, per LOD
    factor and point size, in a store with shuffled nodes (partial levels) and one in input order
    (whole levels, as stores written before shuffled nodes); read throughput."""
    import pyproj

    from siteline.camera.pinhole import Camera
    from siteline.records.params.render import RenderParams
    from siteline.records.tiling import TileSpec
    from siteline.render.zbuffer import render_points
    from siteline.site.spec import make_site_spec
    from siteline.tiles.reader import SceneTiles
    from siteline.tiles.writer import write_tiles

    with tempfile.TemporaryDirectory() as d:
        las = Path(d) / "c.las"
        make_las(las, points, z_noise_m=0.02, half_m=150.0)  # a 300 m surface, as LiDAR samples it
        stores = {}
        for order in ("reversed-morton", "random", "input"):
            r = write_tiles(
                TileInput(las, make_site_spec("b", "EPSG:32618", ORIGIN), pyproj.CRS("EPSG:32618")),
                Path(d) / f"{order}.zarr",
                TileSpec(node_order=order),
                TilingResources(workers=2),
            )
            stores[order] = SceneTiles.open(r.uri)
        cam = Camera.look_at((0, 0, 80), (0, 0, 0), 5645, 4082, 4000.0)
        density = points / 300.0**2
        print(
            f"\n1/8-scale nadir view from 80 m of a {points / 1e6:.0f}M-point scene ({density:.0f} points/m2):"
        )
        print(
            "| node order | lod factor | point size px | points read | covered pixels | read per covered pixel | "
            "coverage | coverage, all levels | read M pts/s |"
        )
        print("|---|---|---|---|---|---|---|---|---|")
        for order, tiles in stores.items():
            every = tiles.points_for_view(cam, 0.125, level=None)
            for size in (1, 3):
                settings = RenderParams(scale=0.125, point_size_px=size)
                full = render_points(every.xyz_m.astype(np.float32), cam, settings)
                for factor in (1.0, 1.41, 2.0, None):
                    t = time.perf_counter()
                    if factor is None:
                        pts = tiles.points_for_view(cam, 0.125, level=None)
                    else:
                        pts = tiles.points_for_view(cam, 0.125, lod_factor=factor, point_size_px=size)
                    sec = time.perf_counter() - t
                    st = pts.stats
                    img = render_points(pts.xyz_m.astype(np.float32), cam, settings)
                    covered = int(img.hit.sum())
                    print(
                        f"| {order} | {factor if factor else 'all levels'} | {size} | {st.points_read:,} | "
                        f"{covered:,} | {st.points_read / max(covered, 1):.2f} | {img.coverage:.2%} | "
                        f"{full.coverage:.2%} | {st.points_read / sec / 1e6:.1f} |"
                    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=20_000_000)
    ap.add_argument("--small", type=int, default=5_000_000)
    ap.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    ap.add_argument("--view-only", action="store_true", help="only the view-read table")
    args = ap.parse_args()
    if args.child:
        child(*args.child)
        return
    if args.view_only:
        view_read(args.points)
        return
    codecs()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in (args.small, args.points):
            path = Path(tmp) / f"{n}.las"
            make_las(path, n)
            plain = run("read", str(path), "-")
            ours = run("tile", str(path), str(Path(tmp) / f"{n}.zarr"))
            rows.append((n, plain, ours))
            path.unlink()
    print(
        "\n| points | laspy read M pts/s | tiling M pts/s (2 workers) | per core | tiling / read | bytes/point | peak MiB |"
    )
    print("|---|---|---|---|---|---|---|")
    for n, plain, ours in rows:
        pr, tr = plain["points"] / plain["seconds"], ours["points"] / ours["seconds"]
        print(
            f"| {n / 1e6:.0f}M | {pr / 1e6:.2f} | {tr / 1e6:.2f} | {tr / 2e6:.2f} | {tr / pr:.2f} | "
            f"{ours['bytes_per_point']:.1f} | {ours['peak_mib']:.0f} |"
        )
    print(
        f"peak memory {args.points / 1e6:.0f}M / {args.small / 1e6:.0f}M = {rows[1][2]['peak_mib'] / rows[0][2]['peak_mib']:.2f}x"
    )
    view_read(args.points)


if __name__ == "__main__":
    main()
