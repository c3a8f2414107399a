"""A pair's view generation and renders beside N busy processes: does a loaded machine cost what its
load explains? (issue: builds that crawl under load)

Runs the work of one release build of a real cloud (tests/data/real/autzen_trim.laz against a later
epoch of it: the pair's labels, view generation and 40 renders) in a child process, first on an idle
machine and then beside N processes that spin on the CPU, for each torch thread setting (torch's default, siteline's adaptive choice, one), and prints the
slowdown beside the fair share: with N busy single-threaded processes on C cores, a job of T threads
gets about C T / (N + T) cores where it had min(C, T), so it should take min(C, T) (N + T) / (C T) as
long.

    python -m bench.load [--busy 2 6] [--threads auto adaptive 1]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _spin() -> None:
    while True:
        pass


def _prepare(home: Path) -> None:
    """A home with autzen and a later epoch of it ingested (site ``az``)."""
    from datetime import UTC, datetime

    from siteline import pipeline
    from siteline.catalog import migrate, open_catalog
    from siteline.catalog.context import StageContext
    from siteline.catalog.engine import make_engine
    from siteline.catalog.sites import add_site
    from siteline.config import Settings, sqlite_url
    from siteline.ingest.options import IngestOptions
    from siteline.site.spec import make_site_spec
    from tests.realdata import AUTZEN, centre_xy, later_epoch

    c = centre_xy(AUTZEN)
    later = later_epoch(
        AUTZEN, home / "later.laz", removed_box=(c[0] - 150, c[1] - 150, c[0] - 50, c[1] - 50), days=300
    )
    settings = Settings(home=home, database_url=sqlite_url(home / "catalog.sqlite"))
    engine = make_engine(settings.database_url)
    migrate.upgrade(engine)
    engine.dispose()
    cat = open_catalog(settings)
    with cat.transaction() as s:
        add_site(s, make_site_spec("az", "EPSG:32610", (493000.0, 4878000.0, 130.0), None))
    for k, path in enumerate((AUTZEN, later)):
        pipeline.ingest(
            StageContext(cat, settings),
            path,
            "az",
            IngestOptions(captured_at=datetime(2020 + k, 5, 1, tzinfo=UTC)),
        )
    cat.dispose()


def _work(home: Path, threads: str) -> dict[str, float]:
    """The pair's labels (made by the warm-up run, then read back), views and 40 renders, timed (in
    this process)."""
    import torch

    from siteline.render.threads import CpuThreads

    if threads not in ("auto", "adaptive"):
        torch.set_num_threads(int(threads))
    governor = CpuThreads("cpu" if threads == "adaptive" else "none")
    from siteline.catalog import open_catalog
    from siteline.config import Settings, sqlite_url
    from siteline.labelsets.store import open_labelled
    from siteline.pairs import execute as ex
    from siteline.pairs.plan import plan_pair
    from siteline.pairs.render import LabelledPair, render_pair_view
    from siteline.progress import no_progress
    from siteline.records.params.pairs import PairParams

    settings = Settings(home=home, database_url=sqlite_url(home / "catalog.sqlite"))
    cat = open_catalog(settings)
    with cat.transaction() as s:
        plan = plan_pair(s, settings.store, 1, PairParams(scale=0.1, point_size_px=3))
    cat.dispose()
    t0 = time.perf_counter()
    t1, t2 = (open_labelled(sc.tiles, sc.label_set) for sc in (plan.t1, plan.t2))
    labels = ex.pair_labels(plan, t1, t2, settings.store, no_progress)
    t_labels = time.perf_counter()
    views = ex.pair_views(plan, t1, t2, no_progress, governor)
    t_views = time.perf_counter()
    pair = LabelledPair.with_labels(t1, t2, labels.uri)
    for v in views.views[:40]:
        governor()
        render_pair_view(pair, v.camera, plan.params, "cpu", plan.colour, plan.site.fence)
    t_end = time.perf_counter()
    return {"labels_s": t_labels - t0, "views_s": t_views - t_labels, "renders_s": t_end - t_views,
            "total_s": t_end - t0, "torch_threads": governor.cap,
            "chosen": sorted(set(governor.chosen))}  # fmt: skip


def _child(home: str, threads: str) -> None:
    print("RESULT " + json.dumps(_work(Path(home), threads)), flush=True)


def _run(home: Path, threads: str, busy: int) -> dict[str, float]:
    spinners = [multiprocessing.Process(target=_spin, daemon=True) for _ in range(busy)]
    for p in spinners:
        p.start()
    try:
        out = subprocess.run(
            [sys.executable, "-m", "bench.load", "--child", str(home), threads],
            capture_output=True,
            text=True,
            check=True,
            cwd=ROOT,
        ).stdout
    finally:
        for p in spinners:
            p.terminate()
    return json.loads([ln for ln in out.splitlines() if ln.startswith("RESULT ")][-1][7:])


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        _child(sys.argv[2], sys.argv[3])
        return
    ap = argparse.ArgumentParser()
    ap.add_argument("--busy", type=int, nargs="+", default=[2, 6])
    ap.add_argument(
        "--threads",
        nargs="+",
        default=["auto", "adaptive", "1"],
        help="torch threads: auto (torch's default, fixed), adaptive (siteline's: the cores the load leaves), or a number",
    )
    args = ap.parse_args()
    cores = os.cpu_count() or 1
    with tempfile.TemporaryDirectory() as d:
        home = Path(d)
        _prepare(home)
        _run(home, "auto", 0)  # warm: labels made, numba caches loaded
        for threads in args.threads:
            idle = _run(home, threads, 0)
            t = int(idle["torch_threads"])
            print(f"{threads} torch threads ({t}), idle: labels {idle['labels_s']:.1f} s, views {idle['views_s']:.1f} s, "
                  f"40 renders {idle['renders_s']:.1f} s, total {idle['total_s']:.1f} s"
                  + (f"; threads chosen {idle['chosen']}" if idle["chosen"] else ""), flush=True)  # fmt: skip
            for n in args.busy:
                loaded = _run(home, threads, n)
                fair = min(cores, t) * (n + t) / (cores * t)
                ratio = loaded["total_s"] / idle["total_s"]
                print(f"  beside {n} busy processes (load {n + t} on {cores} cores): total {loaded['total_s']:.1f} s = "
                      f"{ratio:.2f}x idle, fair share {fair:.2f}x: {ratio / fair:.2f}x of what the load explains "
                      f"(views {loaded['views_s'] / idle['views_s']:.2f}x, renders {loaded['renders_s'] / idle['renders_s']:.2f}x)"
                      + (f"; threads chosen {loaded['chosen']}" if loaded["chosen"] else ""),
                      flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
