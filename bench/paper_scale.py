"""Paper-scale benchmark: one 2-epoch synthetic pair at a real LiDAR density and at 1/4 of it, in the
same run, so growth with density is a ratio. Each stage runs in its own process (its peak memory is
that process's); the figures printed per density are seconds and peak RSS of synth, ingest + tile and
pair processing (labels, view generation, renders), points read per covered pixel per scene, coverage,
valid fraction, seconds per view, and the high/low ratios.

The synthetic photos are 660 x 495 (1/8 of a Zenmuse L2 frame), so the release scale 1.0 used here
renders 660 x 495 images: the paper's 706 x 510 at 1/8 of a 5645 x 4082 frame, within 9 % of its pixels.

With ``--splat world`` (the default) points are drawn as world splats and gaps filled (``--fill``);
``--splat fixed --fill 0`` draws every point as a ``--point-size`` disk, as releases did before.
Scale 2.0 renders 1320 x 990: the paper's 1/4 of a frame, twice its pixels per side.

    python bench/paper_scale.py [--density 1000] [--views 300] [--scale 1.0] [--splat world]
        [--fill 2] [--labels-only] [--knobs JSON] [--json out.json] [--work DIR] [--lidar-only]

``--work DIR`` keeps the generated sites and their catalog, and a later run with the same folder skips
their synthesis and ingest (the 8000 points/m2 site takes about 20 minutes to make).

``--labels-only`` stops each pair after its change labels (the stage that held the pair's peak
memory): their seconds and peak RSS, without the views and renders. ``--tree NAME=PATH`` (with it,
repeatable) labels the same tiles again with the library of the siteline checkout at PATH (each at its
own defaults, in its own process) and prints each tree's seconds and peak beside this one's: today's
rule against another's, measured in one run.
    make bench-scale
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def _peak_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def stage_synth(work: Path, density: float, lidar_only: bool = False) -> dict:
    from siteline.synth import SynthParams, write_site

    t0 = time.perf_counter()
    cfg = SynthParams(epochs=2, density_pts_m2=density, seed=0, photos=not lidar_only, colmap=not lidar_only)
    write_site(work / "site", cfg)
    doc = json.loads((work / "site" / "truth" / "site.json").read_text())
    return {"seconds": time.perf_counter() - t0, "points": [e["points"] for e in doc["epochs"]]}


def _settings(work: Path):  # noqa: ANN202
    from siteline.config import Settings, sqlite_url

    home = work / "home"
    return Settings(home=home, database_url=sqlite_url(home / "catalog.sqlite"))


def stage_ingest(work: Path) -> dict:
    from siteline import pipeline
    from siteline.catalog import migrate, open_catalog
    from siteline.catalog.context import StageContext
    from siteline.catalog.engine import make_engine
    from siteline.catalog.sites import add_site
    from siteline.site.fence import load_fence_geojson
    from siteline.site.spec import make_site_spec
    from siteline.synth import SynthParams

    settings = _settings(work)
    engine = make_engine(settings.database_url)
    migrate.upgrade(engine)
    engine.dispose()
    cat = open_catalog(settings)
    cfg = SynthParams()
    ring = load_fence_geojson(work / "site" / "fence.geojson", cfg.origin)
    with cat.transaction() as s:
        add_site(s, make_site_spec("bench", cfg.crs, cfg.origin, [*ring, ring[0]]))
    doc = json.loads((work / "site" / "truth" / "site.json").read_text())
    t0 = time.perf_counter()
    for e in doc["epochs"]:
        pipeline.ingest(StageContext(cat, settings), work / "site" / e["mission_dir"], "bench", workers=2)
    cat.dispose()
    return {"seconds": time.perf_counter() - t0}


def stage_pair(work: Path, views: int, scale: float, min_valid: float | None, knobs: dict) -> dict:
    from siteline.catalog import open_catalog
    from siteline.catalog.context import StageContext
    from siteline.pairs.stage import process_pair
    from siteline.records.params.pairs import PairParams

    settings = _settings(work)
    cat = open_catalog(settings)
    first: dict[str, float] = {}
    last: dict[str, float] = {}

    def progress(task: str, n: int, total: int | None) -> None:
        now = time.perf_counter()
        first.setdefault(task, now)
        last[task] = now

    extra = {} if min_valid is None else {"min_valid": min_valid}
    params = PairParams(scale=scale, views=views, **knobs, **extra)
    t0 = time.perf_counter()
    out = process_pair(StageContext(cat, settings, progress=progress), 1, params)
    total = time.perf_counter() - t0
    cat.dispose()
    summary = json.loads((Path(out.root) / "summary.json").read_text())
    recs = [v.to_dict() for v in out.views]
    w, h = recs[0]["camera"]["width"], recs[0]["camera"]["height"]
    px = w * scale * h * scale
    covered = np.array([(r["coverage_a"] + r["coverage_b"]) * px for r in recs])
    read = np.array([r["points_read"] for r in recs], dtype=float)
    # stages in the order process_pair runs them: labels, views, renders
    t_views = first.get("renders", t0 + total) - first.get("views", t0)
    t_renders = last.get("renders", t0 + total) - first.get("renders", t0 + total)
    from siteline.camera.pinhole import Camera
    from siteline.views.ground import GroundPlane

    plane = GroundPlane.from_dict(summary["ground_plane"])
    centres = np.array([Camera.from_dict(r["camera"]).center for r in recs])
    heights = plane.height(centres)
    return {
        "camera_height_m": [float(heights.min()), float(np.median(heights)), float(heights.max())],
        "seconds": total,
        "labels_s": first.get("views", t0) - t0,
        "views_s": t_views,
        "renders_s": t_renders,
        "views": len(recs),
        "candidates": summary["candidates"],
        "rejected": summary["rejected"],
        "seconds_per_view": t_renders / max(len(recs), 1),
        "points_read_per_covered_px": float(read.sum() / max(covered.sum(), 1.0)),
        "coverage_median": float(np.median([min(r["coverage_a"], r["coverage_b"]) for r in recs])),
        "valid_median": float(np.median([r["valid"] for r in recs])),
        "valid_min": float(min(r["valid"] for r in recs)),
        "ignore_fraction": float(1 - np.mean([r["valid"] for r in recs])),
        "ignore_causes": {
            c: float(np.mean([r["ignore"].get(c, 0.0) for r in recs])) for c in recs[0]["ignore"]
        },
        "filled": float(np.mean([r["filled"] for r in recs])),
        "probed": summary.get("probed"),
        "image_px": [round(w * scale), round(h * scale)],
    }


def stage_labels(work: Path, knobs: dict) -> dict:
    """The pair's change labels alone (the stage that held the pair's peak memory), with ``knobs``."""
    from siteline.catalog import open_catalog
    from siteline.labelsets.store import open_labelled
    from siteline.pairs.execute import pair_labels
    from siteline.pairs.plan import plan_pair
    from siteline.progress import no_progress
    from siteline.records.params.pairs import PairParams

    settings = _settings(work)
    cat = open_catalog(settings)
    with cat.transaction() as s:
        plan = plan_pair(s, settings.store, 1, PairParams(**knobs), None)
    t1, t2 = (open_labelled(sc.tiles, sc.label_set) for sc in (plan.t1, plan.t2))
    t0 = time.perf_counter()
    labels = pair_labels(plan, t1, t2, settings.store, no_progress)
    total = time.perf_counter() - t0
    cat.dispose()
    return {"seconds": total, "labels_s": total, "radius_m": labels.radius_m}


def child(stage: str, work: str, args: list[str]) -> None:
    work_p = Path(work)
    if stage == "synth":
        res = stage_synth(work_p, float(args[0]), len(args) > 1 and args[1] == "lidar")
    elif stage == "ingest":
        res = stage_ingest(work_p)
    elif stage == "labels":
        res = stage_labels(work_p, json.loads(args[0]))
    else:
        res = stage_pair(
            work_p,
            int(args[0]),
            float(args[1]),
            None if args[2] == "-" else float(args[2]),
            json.loads(args[3]),
        )
    res["peak_mib"] = _peak_mib()
    print("RESULT " + json.dumps(res))


def _run(stage: str, work: Path, *args: str, tree: str | None = None) -> dict:
    """``stage`` in a process of its own; ``tree``: a siteline checkout whose library it runs."""
    env = os.environ | ({"PYTHONPATH": str(Path(tree) / "platform")} if tree else {})
    proc = subprocess.run(
        [sys.executable, __file__, "--child", stage, str(work), *args],
        capture_output=True,
        text=True,
        env=env,
    )
    if proc.returncode:
        sys.stderr.write(proc.stderr[-4000:])
        raise SystemExit(f"stage {stage} failed")
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")][-1]
    return json.loads(line[len("RESULT ") :])


def _run_once(stage: str, work: Path, *args: str) -> dict:
    """``stage`` run in ``work`` unless an earlier run there finished it (its figures kept in
    ``work/<stage>.json``): a kept work folder (``--work``) skips synth and ingest the next time."""
    done = work / f"{stage}.json"
    if done.exists():
        return json.loads(done.read_text())
    res = _run(stage, work, *args)
    done.write_text(json.dumps(res))
    return res


def run_density(root: Path, density: float, args: argparse.Namespace) -> dict:
    work = root / f"d{density:g}"
    work.mkdir(exist_ok=True)
    out = {"density_pts_m2": density}
    out["synth"] = _run_once("synth", work, str(density), "lidar" if args.lidar_only else "photos")
    out["ingest_tile"] = _run_once("ingest", work)
    if args.labels_only:
        shutil.rmtree(work / "home" / "stores" / "labels", ignore_errors=True)  # a kept folder's last labels
    mv = "-" if args.min_valid is None else str(args.min_valid)
    knobs = {
        "point_size_px": args.point_size,
        "lod_factor": args.lod_factor,
        "splat": args.splat,
        "fill_px": args.fill,
        **args.knobs,
    }
    if args.labels_only:
        label_knobs = json.dumps(
            {k: v for k, v in knobs.items() if k not in ("point_size_px", "splat", "fill_px")}
        )
        out["pair"] = _run("labels", work, label_knobs)
        for name, tree in args.tree:
            shutil.rmtree(work / "home" / "stores" / "labels", ignore_errors=True)
            out.setdefault("trees", {})[name] = _run("labels", work, label_knobs, tree=tree)
    else:
        out["pair"] = _run("pair", work, str(args.views), str(args.scale), mv, json.dumps(knobs))
    return out


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        child(sys.argv[2], sys.argv[3], sys.argv[4:])
        return
    ap = argparse.ArgumentParser()
    ap.add_argument("--density", type=float, default=1000.0, help="points/m2 of the dense run")
    ap.add_argument("--ratio", type=float, default=4.0, help="the sparse run has density / ratio")
    ap.add_argument("--views", type=int, default=300)
    ap.add_argument(
        "--scale", type=float, default=None,
        help="render scale (default 1.0 of the synthetic photos' 660 x 495; with --lidar-only 0.125 of the "
        "planned cameras' whole 5280 x 3956 frames: the same images)",
    )  # fmt: skip
    ap.add_argument(
        "--min-valid", type=float, default=None, help="PairParams.min_valid (default: its default)"
    )
    ap.add_argument("--point-size", type=int, default=3, help="px (3: every preset's)")
    ap.add_argument("--lod-factor", type=float, default=1.0)
    ap.add_argument("--splat", choices=("world", "fixed"), default="world", help="how big a point is drawn")
    ap.add_argument("--fill", type=int, default=2, help="gap fill radius, px (0: none)")
    ap.add_argument(
        "--labels-only",
        action="store_true",
        help="of the pair, its change labels only (their time and peak memory)",
    )
    ap.add_argument(
        "--knobs", type=json.loads, default={},
        help='more pair knobs as JSON, e.g. \'{"surface_probe": 0}\' (the labels without the probe)',
    )  # fmt: skip
    ap.add_argument(
        "--tree", action="append", default=[], type=lambda s: tuple(s.split("=", 1)),
        help="with --labels-only: NAME=PATH, label the same tiles with the siteline checkout at PATH too",
    )  # fmt: skip
    ap.add_argument(
        "--lidar-only", action="store_true",
        help="scans without photos: the pair's views are planned from the scene (its planned survey)",
    )  # fmt: skip
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument(
        "--work", type=Path, default=None,
        help="keep the generated sites and their catalog here, and reuse what an earlier run left (synth and ingest are skipped)",
    )  # fmt: skip
    args = ap.parse_args()
    if args.scale is None:
        args.scale = 0.125 if args.lidar_only else 1.0
    with contextlib.ExitStack() as stack:
        root = args.work or Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="paper-scale-")))
        root.mkdir(parents=True, exist_ok=True)
        runs = [run_density(root, args.density / args.ratio, args), run_density(root, args.density, args)]
    lo, hi = runs
    keys = ("seconds", "labels_s", "views_s", "renders_s", "peak_mib", "points_read_per_covered_px")
    ratios = {
        "points": sum(hi["synth"]["points"]) / sum(lo["synth"]["points"]),
        "ingest_tile_s": hi["ingest_tile"]["seconds"] / lo["ingest_tile"]["seconds"],
        **{k: hi["pair"][k] / max(lo["pair"][k], 1e-9) for k in keys if k in hi["pair"]},
    }
    report = {"runs": runs, "ratios_dense_over_sparse": ratios}
    for r in runs:
        if args.labels_only:
            p = r["pair"]
            print(
                f"{r['density_pts_m2']:g} pts/m2 ({sum(r['synth']['points']):,} points): synth {r['synth']['seconds']:.0f} s, "
                f"ingest+tile {r['ingest_tile']['seconds']:.0f} s ({r['ingest_tile']['peak_mib']:.0f} MiB), "
                f"labels {p['labels_s']:.1f} s at r = {p['radius_m']:.3f} m ({p['peak_mib']:.0f} MiB peak)"
                + "".join(
                    f"; {name}: {t['labels_s']:.1f} s ({t['peak_mib']:.0f} MiB), this tree {p['labels_s'] / t['labels_s']:.2f}x"
                    for name, t in r.get("trees", {}).items()
                )
            )
            continue
        p = r["pair"]
        print(
            f"{r['density_pts_m2']:g} pts/m2 ({sum(r['synth']['points']):,} points): synth {r['synth']['seconds']:.0f} s "
            f"({r['synth']['peak_mib']:.0f} MiB), ingest+tile {r['ingest_tile']['seconds']:.0f} s "
            f"({r['ingest_tile']['peak_mib']:.0f} MiB), pair {p['seconds']:.0f} s ({p['peak_mib']:.0f} MiB): "
            f"labels {p['labels_s']:.0f} s, views {p['views_s']:.0f} s ({p['candidates']} candidates), "
            f"renders {p['renders_s']:.0f} s = {p['seconds_per_view']:.2f} s/view for {p['views']} views at "
            f"{p['image_px'][0]}x{p['image_px'][1]}; {p['points_read_per_covered_px']:.2f} points read per "
            f"covered pixel per scene; median coverage {p['coverage_median']:.3f}, median valid "
            f"{p['valid_median']:.3f} (min {p['valid_min']:.2f}); ignore {p['ignore_fraction']:.1%} "
            f"({', '.join(f'{k} {v:.1%}' for k, v in p['ignore_causes'].items())}), filled {p['filled']:.1%}; "
            f"{p['probed']} candidates probed, rejected {p['rejected']}; camera heights min/median/max "
            f"{', '.join(f'{h:.1f}' for h in p['camera_height_m'])} m"
        )
    print("dense / sparse: " + ", ".join(f"{k} {v:.2f}x" for k, v in ratios.items()))
    if args.json:
        args.json.write_text(json.dumps(report, indent=1) + "\n")


if __name__ == "__main__":
    main()
