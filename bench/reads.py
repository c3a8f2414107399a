"""A view's tile read: ``SceneTiles.points_for_view`` throughput cold (a fresh process, nothing
cached but what the OS holds), warm (the same views again, in turn: a second pass that overflows
the chunk cache decodes again what the first evicted) and again (each view read twice in a row, the
second timed: its chunks decoded, the read path alone), on a dense generated scene, for this
checkout and another one's library (``--tree before=PATH``) in the same run, with a checksum of
every read (the trees must read the same points).

    python -m bench.reads [--points 20000000] [--half 50] [--views 12] [--tree before=/path/to/checkout]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from bench.ingest import ORIGIN, make_las

REPO = Path(__file__).resolve().parents[1]


def cameras(n: int, half_m: float) -> list[object]:
    """``n`` views of a release frame (5280 x 3956 px, focal 3700 px) over the scene: nadir and
    oblique, from 25 to 60 m, spread over it."""
    from siteline.camera.pinhole import Camera

    rng = np.random.default_rng(7)
    out = []
    for k in range(n):
        x, y = rng.uniform(-0.6 * half_m, 0.6 * half_m, 2)
        h = float(rng.uniform(25.0, 60.0))
        tilt = 0.0 if k % 2 == 0 else float(rng.uniform(0.3, 0.8)) * h
        out.append(Camera.look_at((x, y, h), (x + tilt, y, 0.0), 5280, 3956, 3700.0))
    return out


def child(store: str, views: int, half_m: float) -> None:
    """Read every view twice in this process and print the figures as JSON."""
    from siteline.tiles.reader import SceneTiles

    cams = cameras(views, half_m)
    t0 = time.perf_counter()
    tiles = SceneTiles.open(store)
    opened = time.perf_counter() - t0
    passes = []
    sums = []
    for _ in range(2):
        seconds, points = [], []
        for cam in cams:
            t = time.perf_counter()
            pts = tiles.points_for_view(cam, 0.125, attributes=("rgb", "class"))
            seconds.append(time.perf_counter() - t)
            points.append(len(pts.xyz_m))
            if len(sums) < len(cams):
                h = hashlib.sha256(np.ascontiguousarray(pts.xyz_m).tobytes())
                for name in ("rgb", "class"):
                    h.update(np.ascontiguousarray(pts.attributes[name]).tobytes())
                h.update(np.ascontiguousarray(pts.spacing_m).tobytes())
                sums.append(h.hexdigest()[:16])
        passes.append({"seconds": seconds, "points": points})
    seconds, points = [], []
    for cam in cams:
        tiles.points_for_view(cam, 0.125, attributes=("rgb", "class"))
        t = time.perf_counter()
        pts = tiles.points_for_view(cam, 0.125, attributes=("rgb", "class"))
        seconds.append(time.perf_counter() - t)
        points.append(len(pts.xyz_m))
    passes.append({"seconds": seconds, "points": points})
    print(json.dumps({"open_s": opened, "passes": passes, "checksums": sums}))


def run_tree(platform: Path, store: str, views: int, half_m: float) -> dict:
    env = dict(os.environ, PYTHONPATH=f"{platform}{os.pathsep}{REPO}")
    cmd = [
        sys.executable,
        "-m",
        "bench.reads",
        "--child",
        store,
        "--views",
        str(views),
        "--half",
        str(half_m),
    ]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True, cwd=REPO)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=20_000_000)
    ap.add_argument("--half", type=float, default=50.0, help="half the scene's side (metres)")
    ap.add_argument("--views", type=int, default=12)
    ap.add_argument("--tree", action="append", default=[], help="NAME=PATH of another checkout")
    ap.add_argument("--store", help="a tile store made before (skips the build)")
    ap.add_argument("--keep", help="build the store in this folder and keep it (for --store later)")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.child, args.views, args.half)
        return
    trees = {"today": REPO / "platform"} | {
        n: Path(p).resolve() / "platform" for n, p in (t.split("=", 1) for t in args.tree)
    }
    with tempfile.TemporaryDirectory() as tmp:
        d = args.keep or tmp
        Path(d).mkdir(parents=True, exist_ok=True)
        store = args.store
        if store is None:
            import pyproj

            from siteline.pointpass import TilingResources
            from siteline.records.tiling import TileSpec
            from siteline.site.spec import make_site_spec
            from siteline.tiles.writer import TileInput, write_tiles

            las = Path(d) / "c.las"
            make_las(las, args.points, z_noise_m=0.02, half_m=args.half)
            r = write_tiles(
                TileInput(las, make_site_spec("b", "EPSG:32618", ORIGIN), pyproj.CRS("EPSG:32618")),
                Path(d) / "s.zarr",
                TileSpec(),
                TilingResources(workers=2),
            )
            store = r.uri
        density = args.points / (2 * args.half) ** 2
        print(f"{args.views} views at 1/8 of a 5280 x 3956 frame over {args.points / 1e6:.0f}M points "
              f"({density:,.0f} points/m2); each tree in a fresh process, its views read twice\n")  # fmt: skip
        print(
            "| tree | points a view | first view s | cold M pts/s | warm M pts/s | again M pts/s | cold s a view "
            "| warm s a view | again s a view |"
        )
        print("|---|---|---|---|---|---|---|---|---|")
        results = {}
        # alternate the trees twice so neither always runs on a warmer OS cache
        for name in [*trees, *trees]:
            got = run_tree(trees[name], store, args.views, args.half)
            results.setdefault(name, []).append(got)
            cold, warm, again = got["passes"]
            n = sum(cold["points"])
            rate = lambda p: f"{sum(p['points']) / sum(p['seconds']) / 1e6:.2f}"  # noqa: E731
            each = lambda p: f"{sum(p['seconds']) / len(p['seconds']):.3f}"  # noqa: E731
            print(
                f"| {name} | {n / len(cold['points']):,.0f} | {cold['seconds'][0]:.3f} | {rate(cold)} | "
                f"{rate(warm)} | {rate(again)} | {each(cold)} | {each(warm)} | {each(again)} |"
            )
        sums = {n: r[0]["checksums"] for n, r in results.items()}
        same = len({tuple(v) for v in sums.values()}) == 1
        print(f"\nreads identical across trees: {same}")
        if len(trees) > 1:
            base = results["today"]
            for name in trees:
                if name == "today":
                    continue
                for k, label in ((0, "cold"), (1, "warm"), (2, "again")):
                    mine = np.median([sum(r["passes"][k]["seconds"]) for r in base])
                    theirs = np.median([sum(r["passes"][k]["seconds"]) for r in results[name]])
                    print(f"{label}: today reads in {mine / theirs:.2f}x the time of {name}")


if __name__ == "__main__":
    main()
