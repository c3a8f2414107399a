"""A pair's renders, this checkout against another's library in the same run: the views a processed
pair kept (its ``summary.json``), rendered again on both scenes with the pair's published labels by
``siteline.pairs.render.render_pair_view``, each tree in a fresh process (nothing cached but what the
OS holds), all trees in one order: the one this checkout's pair renders in (``--order tour``:
siteline.pairs.execute.look_tour) or the summary's (``sampled``). Prints per tree the seconds a view
(all of them: the chunk caches warm over consecutive views as in a pair; and the first ``--first``
alone: a release of a few views pays its reads cold), the share of it in
``SceneTiles.points_for_view``, and a checksum of the images and masks in that order (equal where the
trees draw alike). ``--reads-only``: the views' reads alone, both scenes one after the other, in
points a second.

The pair comes from ``bench/paper_scale.py --work DIR`` (``DIR/d8000`` holds the 8,000 points/m2
site and its pair, processed with the knobs given here again):

    python -m bench.renders --work /tmp/ps/d8000 [--views 300] [--first 12] [--tree before=PATH]
        [--order tour|sampled] [--reads-only] [--rounds 1]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _summary(work: Path) -> dict:
    """The summary of the pair output named by BENCH_PAIR_OUTPUT (a folder's name under
    home/stores/pairs), else of the pair output with most views under ``work``/home."""
    found = sorted((work / "home").rglob("summary.json"))
    docs = {p.parent.name: json.loads(p.read_text()) for p in found}
    docs = {k: d for k, d in docs.items() if "views" in d}
    if not docs:
        raise SystemExit(
            f"{work}: no processed pair (summary.json) under home/; run bench/paper_scale.py first"
        )
    name = os.environ.get("BENCH_PAIR_OUTPUT") or max(docs, key=lambda k: len(docs[k]["views"]))
    return docs[name]


def tour(summary: dict) -> list[int]:
    """The pair's views in the order this checkout's pair renders them
    (siteline.pairs.execute.look_tour over the pair's ground plane)."""
    from siteline.camera.pinhole import Camera
    from siteline.pairs.execute import look_tour
    from siteline.records.pairs import ViewStrategy
    from siteline.views.generate import SyntheticView
    from siteline.views.ground import GroundPlane

    views = [
        SyntheticView(str(k), v["strategy"], ViewStrategy(1.0, False, 0.0), Camera.from_dict(v["camera"]))
        for k, v in enumerate(summary["views"])
    ]
    ground = GroundPlane.from_dict(summary["ground_plane"])
    return [int(v.parent) for v in look_tour(views, ground)]


def child(work: str, order: list[int], knobs: dict, reads_only: bool = False) -> None:
    """Render the pair's views ``order`` (positions in its summary) in this process, or only read
    their points (``reads_only``: both scenes, as a render reads them); print the figures as JSON."""
    from siteline.camera.pinhole import Camera
    from siteline.catalog import open_catalog
    from siteline.config import Settings, sqlite_url
    from siteline.labelsets.store import open_labelled
    from siteline.pairs.plan import plan_pair
    from siteline.pairs.render import LabelledPair, render_pair_view
    from siteline.records.params.pairs import PairParams
    from siteline.tiles.reader import SceneTiles

    summary = _summary(Path(work))
    home = Path(work) / "home"
    settings = Settings(home=home, database_url=sqlite_url(home / "catalog.sqlite"))
    cat = open_catalog(settings)
    params = PairParams(**knobs)
    with cat.transaction() as s:
        plan = plan_pair(s, settings.store, summary["pair"], params, None)
    t1, t2 = (open_labelled(sc.tiles, sc.label_set) for sc in (plan.t1, plan.t2))
    scenes = LabelledPair.with_labels(t1, t2, summary["labels"]["uri"])
    read_s = [0.0]
    real = SceneTiles.points_for_view

    def timed(self, *a, **kw):  # noqa: ANN001, ANN002, ANN003, ANN202
        t = time.perf_counter()
        try:
            return real(self, *a, **kw)
        finally:
            read_s[0] += time.perf_counter() - t

    SceneTiles.points_for_view = timed  # type: ignore[method-assign]
    cams = [Camera.from_dict(summary["views"][i]["camera"]) for i in order]
    seconds, reads, points = [], [], 0
    digest = hashlib.sha256()
    for cam in cams:
        if reads_only:
            t = time.perf_counter()
            for tiles in (scenes.t1, scenes.t2):
                got = tiles.points_for_view(
                    cam, params.scale, attributes=("rgb", "change"), lod_factor=params.lod_factor,
                    point_size_px=params.point_size_px, level="auto",
                )  # fmt: skip
                points += got.stats.points_read
                digest.update(got.xyz_m.tobytes())
            seconds.append(time.perf_counter() - t)
            reads.append(seconds[-1])
            continue
        r0, t = read_s[0], time.perf_counter()
        r = render_pair_view(scenes, cam, params, "cpu", plan.colour, plan.site.fence, None)
        seconds.append(time.perf_counter() - t)
        reads.append(read_s[0] - r0)
        points += r.points_read
        for image in (r.a, r.b, r.mask):
            digest.update(image.tobytes())
    cat.dispose()
    print(
        "RESULT "
        + json.dumps({"seconds": seconds, "reads": reads, "points": points, "sha": digest.hexdigest()})
    )


def _run(work: Path, order: list[int], knobs: dict, tree: str | None, reads_only: bool) -> dict:
    env = os.environ | {"PYTHONPATH": str(Path(tree) / "platform") if tree else str(REPO / "platform")}
    proc = subprocess.run(
        [sys.executable, "-m", "bench.renders", "--child", str(work), json.dumps(order), json.dumps(knobs), str(reads_only)],
        capture_output=True, text=True, env=env, cwd=REPO,
    )  # fmt: skip
    if proc.returncode:
        sys.stderr.write(proc.stderr[-4000:])
        raise SystemExit(f"the renders of {tree or 'this checkout'} failed")
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")][-1]
    return json.loads(line[len("RESULT ") :])


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        child(sys.argv[2], json.loads(sys.argv[3]), json.loads(sys.argv[4]), sys.argv[5] == "True")
        return
    ap = argparse.ArgumentParser()
    ap.add_argument(
        "--work", type=Path, required=True, help="a paper_scale.py density folder (e.g. DIR/d8000)"
    )
    ap.add_argument("--views", type=int, default=300, help="the pair's first views rendered")
    ap.add_argument("--first", type=int, default=12, help="the views also quoted alone (a release's few)")
    ap.add_argument("--tree", action="append", default=[], help="NAME=PATH of another checkout")
    ap.add_argument(
        "--order", choices=("tour", "sampled"), default="tour",
        help="the order a pair renders in (this checkout's tour by where the views look), or the summary's",
    )  # fmt: skip
    ap.add_argument(
        "--drop-caches", action="store_true",
        help="empty the OS page cache before each tree (root on Linux): reads from the disk, cold",
    )  # fmt: skip
    ap.add_argument("--pair-output", help="the pair output's folder name (default: the one of most views)")
    ap.add_argument("--reads-only", action="store_true", help="only read each view's points (both scenes)")
    ap.add_argument("--rounds", type=int, default=1, help="each tree this many times, alternated")
    args = ap.parse_args()
    if args.pair_output:
        os.environ["BENCH_PAIR_OUTPUT"] = args.pair_output
    summary = _summary(args.work)
    p = summary["params"]
    knobs = {k: p[k] for k in ("scale", "point_size_px", "lod_factor", "splat", "fill_px") if k in p}
    trees = [("today", None), *(tuple(t.split("=", 1)) for t in args.tree)]
    n = min(args.views, len(summary["views"]))
    order = tour(summary)[:n] if args.order == "tour" else list(range(n))
    print(f"{args.work}: pair {summary['pair']}, {n} of its {len(summary['views'])} views, knobs {knobs}")
    for rnd in range(args.rounds):
        for name, tree in trees:
            if args.drop_caches:
                os.sync()
                Path("/proc/sys/vm/drop_caches").write_text("3\n")
            res = _run(args.work, order, knobs, tree, args.reads_only)
            s, rd = res["seconds"], res["reads"]
            k = min(args.first, n)
            if args.reads_only:
                print(
                    f"round {rnd + 1} {name}: {n} views read (both scenes) {sum(s):.1f} s, "
                    f"{res['points'] / sum(s) / 1e6:.2f} M points/s; the first {k}: {sum(s[:k]):.2f} s; "
                    f"{res['points']:,} points; xyz {res['sha'][:12]}"
                )
                continue
            print(
                f"round {rnd + 1} {name}: {n} views {sum(s):.1f} s = {sum(s) / n:.3f} s a view "
                f"(reads {sum(rd) / n:.3f}); the first {k}: {sum(s[:k]) / k:.3f} s a view (reads "
                f"{sum(rd[:k]) / k:.3f}); first view {s[0]:.2f} s; {res['points']:,} points read; "
                f"images {res['sha'][:12]}"
            )


if __name__ == "__main__":
    main()
