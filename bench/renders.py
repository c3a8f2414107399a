"""A pair's renders, this checkout against another's library in the same run: the views a processed
pair kept (its ``summary.json``), rendered again on both scenes with the pair's published labels by
``siteline.pairs.render.render_pair_view``, each tree in a fresh process (nothing cached but what the
OS holds), the views in the pair's order. Prints per tree the seconds a view (all of them: the chunk
cache warm over consecutive views as in a pair; and the first ``--first`` alone: a release of a few
views pays its reads cold), the share of it in ``SceneTiles.points_for_view``, and a checksum of the
masks and images (equal where the trees draw alike).

The pair comes from ``bench/paper_scale.py --work DIR`` (``DIR/d8000`` holds the 8,000 points/m2
site and its pair, processed with the knobs given here again):

    python -m bench.renders --work /tmp/ps/d8000 [--views 300] [--first 12] [--tree before=PATH]
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
    found = sorted((work / "home").rglob("summary.json"))
    pairs = [p for p in found if "views" in json.loads(p.read_text())]
    if not pairs:
        raise SystemExit(
            f"{work}: no processed pair (summary.json) under home/; run bench/paper_scale.py first"
        )
    return json.loads(pairs[-1].read_text())


def _near_order(cams: list) -> list[int]:
    """A greedy tour of the views by the ground point each looks at (its axis met with z = 0, the
    synthetic site's ground, or 30 m along it when level): consecutive views share chunks."""
    import numpy as np

    at = []
    for c in cams:
        f = c.forward
        t = -c.center[2] / f[2] if f[2] < -0.1 else 30.0
        at.append(c.center[:2] + t * f[:2])
    pts = np.array(at)
    left = list(range(1, len(cams)))
    order = [0]
    while left:
        d = np.linalg.norm(pts[left] - pts[order[-1]], axis=1)
        order.append(left.pop(int(np.argmin(d))))
    return order


def child(work: str, views: int, knobs: dict, near: bool = False) -> None:
    """Render the pair's first ``views`` views in this process; print the figures as JSON."""
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
    cams = [Camera.from_dict(v["camera"]) for v in summary["views"][:views]]
    if near:
        cams = [cams[i] for i in _near_order(cams)]
    seconds, reads, points = [], [], 0
    digest = hashlib.sha256()
    for cam in cams:
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


def _run(work: Path, views: int, knobs: dict, tree: str | None, order: str = "pair") -> dict:
    env = os.environ | {"PYTHONPATH": str(Path(tree) / "platform") if tree else str(REPO / "platform")}
    proc = subprocess.run(
        [sys.executable, "-m", "bench.renders", "--child", str(work), str(views), json.dumps(knobs), order],
        capture_output=True, text=True, env=env, cwd=REPO,
    )  # fmt: skip
    if proc.returncode:
        sys.stderr.write(proc.stderr[-4000:])
        raise SystemExit(f"the renders of {tree or 'this checkout'} failed")
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")][-1]
    return json.loads(line[len("RESULT ") :])


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        child(sys.argv[2], int(sys.argv[3]), json.loads(sys.argv[4]), sys.argv[5] == "near")
        return
    ap = argparse.ArgumentParser()
    ap.add_argument(
        "--work", type=Path, required=True, help="a paper_scale.py density folder (e.g. DIR/d8000)"
    )
    ap.add_argument("--views", type=int, default=300, help="the pair's first views rendered")
    ap.add_argument("--first", type=int, default=12, help="the views also quoted alone (a release's few)")
    ap.add_argument("--tree", action="append", default=[], help="NAME=PATH of another checkout")
    ap.add_argument(
        "--order", choices=("pair", "near"), default="pair",
        help="the pair's order, or a tour by where the views look (consecutive views share chunks)",
    )  # fmt: skip
    ap.add_argument("--rounds", type=int, default=1, help="each tree this many times, alternated")
    args = ap.parse_args()
    summary = _summary(args.work)
    p = summary["params"]
    knobs = {k: p[k] for k in ("scale", "point_size_px", "lod_factor", "splat", "fill_px") if k in p}
    trees = [("today", None), *(tuple(t.split("=", 1)) for t in args.tree)]
    n = min(args.views, len(summary["views"]))
    print(f"{args.work}: pair {summary['pair']}, {n} of its {len(summary['views'])} views, knobs {knobs}")
    for rnd in range(args.rounds):
        for name, tree in trees:
            res = _run(args.work, n, knobs, tree, args.order)
            s, rd = res["seconds"], res["reads"]
            k = min(args.first, n)
            print(
                f"round {rnd + 1} {name}: {n} views {sum(s):.1f} s = {sum(s) / n:.3f} s a view "
                f"(reads {sum(rd) / n:.3f}); the first {k}: {sum(s[:k]) / k:.3f} s a view (reads "
                f"{sum(rd[:k]) / k:.3f}); first view {s[0]:.2f} s; {res['points']:,} points read; "
                f"images {res['sha'][:12]}"
            )


if __name__ == "__main__":
    main()
