"""Release benchmark: 3D label throughput (tiled, both directions) beside a whole-cloud cKDTree on the
same data in the same run, seconds per view rendered on both scenes, and the end-to-end demo time.

    python bench/release.py [--density 10] [--demo]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pyproj
from scipy.spatial import cKDTree

from siteline.pointpass import TilingResources
from siteline.tiles.writer import TileInput


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--density", type=float, default=10.0)
    ap.add_argument("--views", type=int, default=12)
    ap.add_argument(
        "--demo", action="store_true", help="also time `siteline demo` end to end in a fresh home"
    )
    args = ap.parse_args()
    from siteline.camera.pinhole import Camera
    from siteline.labels.change import change_flags
    from siteline.labels.store import write_labels
    from siteline.pairs.render import LabelledPair, render_pair_view
    from siteline.records.params.pairs import PairParams
    from siteline.site.fence import load_fence_geojson
    from siteline.site.spec import make_site_spec
    from siteline.synth import LAS_RELPATH, SynthParams, write_site
    from siteline.tiles.reader import SceneTiles
    from siteline.tiles.writer import write_tiles

    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        cfg = SynthParams(epochs=2, density_pts_m2=args.density)
        write_site(d / "site", cfg)
        doc = json.loads((d / "site" / "truth" / "site.json").read_text())
        ring = load_fence_geojson(d / "site" / "fence.geojson", cfg.origin)
        site = make_site_spec("b", cfg.crs, cfg.origin, [*ring, ring[0]])
        ign = site.taxonomy.ignored_lut()
        tiles = []
        for i, ep in enumerate(doc["epochs"]):
            r = write_tiles(
                TileInput(d / "site" / ep["mission_dir"] / LAS_RELPATH, site, pyproj.CRS(cfg.crs)),
                d / f"s{i}.zarr",
                resources=TilingResources(workers=1),
            )
            tiles.append(SceneTiles.open(r.uri))
        n = sum(t.point_count for t in tiles)
        t0 = time.perf_counter()
        res = write_labels(tiles[0], tiles[1], 0.4, ign, d / "labels.zarr")
        tiled = time.perf_counter() - t0
        # the baseline: whole clouds in memory, one cKDTree per direction (float64), same definition
        pa = tiles[0].points(attributes=("class",))
        pb = tiles[1].points(attributes=("class",))
        xa, xb = pa.xyz_m.astype(np.float32), pb.xyz_m.astype(np.float32)
        ca, cb = pa.attributes["class"], pb.attributes["class"]
        t0 = time.perf_counter()
        for a, b, cls_b in ((pa.xyz_m, pb.xyz_m, cb), (pb.xyz_m, pa.xyz_m, ca)):
            tree = cKDTree(b[~ign[cls_b]])
            tree.query(a, k=1, distance_upper_bound=0.4)
        whole = time.perf_counter() - t0
        t0 = time.perf_counter()
        for a, cls_a, b, cls_b in ((xa, ca, xb, cb), (xb, cb, xa, ca)):
            change_flags(a, cls_a, b, cls_b, 0.4, ign)
        whole_ours = time.perf_counter() - t0
        print(f"labels, {n:,} points (both scenes, both directions):")
        print("| method | seconds | points/s |")
        print("|---|---|---|")
        print(
            f"| siteline tiled (tile + halo, pykdtree float32, reads from Zarr) | {tiled:.2f} | {n / tiled:,.0f} |"
        )
        print(
            f"| whole-cloud change_flags (pykdtree float32, in memory) | {whole_ours:.2f} | {n / whole_ours:,.0f} |"
        )
        print(f"| whole-cloud cKDTree float64 (query only, in memory) | {whole:.2f} | {n / whole:,.0f} |")
        pair = LabelledPair.with_labels(tiles[0], tiles[1], str(d / "labels.zarr"))
        cams = [
            Camera.from_dict(c["camera"])
            for c in json.loads(
                (d / "site" / "truth" / doc["epochs"][1]["name"] / "cameras.json").read_text()
            )
        ][: args.views]
        for scale, ps in ((0.125, 1), (0.5, 3), (1.0, 1)):
            params = PairParams(scale=scale, point_size_px=ps)
            render_pair_view(pair, cams[0], params)  # warm the caches
            t0 = time.perf_counter()
            for cam in cams:
                render_pair_view(pair, cam, params)
            sec = (time.perf_counter() - t0) / len(cams)
            w, h = cams[0].scaled(scale).width, cams[0].scaled(scale).height
            print(f"seconds per view (both scenes, {w}x{h}, {ps} px): {sec:.3f}")
        del res
    if args.demo:
        with tempfile.TemporaryDirectory() as home:
            t0 = time.perf_counter()
            subprocess.run(
                [sys.executable, "-m", "siteline", "demo"],
                env={**__import__("os").environ, "SITELINE_HOME": home},
                check=True,
                capture_output=True,
            )
            print(
                f"end-to-end `siteline demo` (4 epochs, generate -> evaluate): {time.perf_counter() - t0:.0f} s"
            )


if __name__ == "__main__":
    main()
