"""Store benchmark: the pipeline's stages with the stores in a local folder against the same stages
with the stores on an object store, in the same run. The object store is moto's S3 server in its own
process on 127.0.0.1 (a Python server: slower than MinIO or S3 per request, so the ratios are an
upper bound on what the object-store path itself costs).

    python -m bench.stores [--density 10] [--views 6]
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from siteline.catalog.context import StageContext
from siteline.pointpass import TilingResources
from siteline.records.release import ReleaseOptions

REPO = Path(__file__).resolve().parents[1]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start_s3() -> tuple[subprocess.Popen, str]:
    port = _free_port()
    proc = subprocess.Popen(
        [str(Path(sys.executable).parent / "moto_server"), "-H", "127.0.0.1", "-p", str(port)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    endpoint = f"http://127.0.0.1:{port}"
    for _ in range(100):
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            return proc, endpoint
        except OSError:
            time.sleep(0.1)
    proc.kill()
    raise SystemExit("moto_server did not start")


def _run(root: Path, site_dir: Path, store_url: str, views: int) -> dict[str, float]:
    from siteline.catalog import open_catalog
    from siteline.ingest.stage import ingest_mission
    from siteline.pairs.stage import process_pair
    from siteline.records.params.pairs import PairParams
    from siteline.records.params.release import ReleaseParams
    from siteline.release.stage import build_release
    from siteline.tiles.stage import tile_scene
    from tests.sitehelpers import epoch_dirs, make_home

    settings = make_home(root, site_dir=site_dir, store_url=store_url)
    settings.store.ensure()
    cat = open_catalog(settings)
    params = PairParams(scale=0.25, point_size_px=3, views=views, seed=0, min_coverage=0.2)
    t: dict[str, float] = {}
    t0 = time.perf_counter()
    scenes = [
        ingest_mission(StageContext(cat, settings), m, "demo").scene_id for m in epoch_dirs(site_dir)[:2]
    ]
    t["ingest (2 missions)"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    for sid in scenes:
        tile_scene(StageContext(cat, settings), sid, resources=TilingResources(workers=1))
    t["tile (2 scenes)"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    process_pair(StageContext(cat, settings), 1, params)
    t["process pair (labels, views, renders)"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    build_release(
        StageContext(cat, settings),
        "demo",
        "bench",
        ReleaseParams(params),
        options=ReleaseOptions(pair_ids=[1]),
    )
    t["build release (copies renders out)"] = time.perf_counter() - t0
    cat.dispose()
    return t


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--density", type=float, default=10.0)
    ap.add_argument("--views", type=int, default=6)
    args = ap.parse_args()
    from siteline.synth import SynthParams, write_site

    proc, endpoint = _start_s3()
    conf = {"endpoint_url": endpoint, "key": "bench", "secret": "bench"}
    os.environ["FSSPEC_S3"] = json.dumps(conf)
    import fsspec

    fsspec.config.conf["s3"] = conf
    fsspec.filesystem("s3").mkdir("bench")
    try:
        with tempfile.TemporaryDirectory() as d:
            d = Path(d)
            write_site(d / "site", SynthParams(epochs=2, density_pts_m2=args.density, seed=3))
            local = _run(d / "local", d / "site", "", args.views)
            remote = _run(d / "s3", d / "site", "s3://bench/stores", args.views)
    finally:
        proc.terminate()
    print(f"density {args.density} pts/m2, {args.views} views; seconds, local folder vs S3 (moto, loopback)")
    print("| stage | local s | S3 s | S3 / local |\n|---|---|---|---|")
    for k in local:
        print(f"| {k} | {local[k]:.2f} | {remote[k]:.2f} | {remote[k] / local[k]:.2f}x |")
    lt, rt = sum(local.values()), sum(remote.values())
    print(f"| total | {lt:.2f} | {rt:.2f} | {rt / lt:.2f}x |")


if __name__ == "__main__":
    main()
