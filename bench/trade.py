"""The speed/accuracy trade, measured end to end on a synthetic site with known truth.

Sweeps render scale x point size x splats (fixed disks, or world splats with the gap fill) x
level-of-detail factor x label radius multiplier (and, for the 3D labels, the nearest-neighbour
backend); for each setting: seconds, peak memory, points read, coverage, valid share (pixels the
mask does not ignore), filled share, agreement of the 2D mask with the ground-truth change rendered
through the same view (F1 and IoU of the changed class) and the 3D label accuracy. Writes trade.csv,
trade.md and two plots with the Pareto front marked.
"""

from __future__ import annotations

import csv
import itertools
import json
import time
import tracemalloc
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import laspy
import numpy as np
import pyproj

from siteline.camera.pinhole import Camera
from siteline.labels.change import CHANGED, IGNORED, UNCHANGED, Matching, change_flags, median_spacing
from siteline.pairs.render import pair_mask
from siteline.pairs.sources import TilePointSource
from siteline.pointpass import TilingResources
from siteline.release.metrics import confusion, scores
from siteline.render.settings import RenderSettings
from siteline.render.zbuffer import render_points
from siteline.site.fence import inside_fence, load_fence_geojson
from siteline.site.spec import SiteSpec, make_site_spec
from siteline.site.taxonomy import default_taxonomy
from siteline.synth import LAS_RELPATH, SynthConfig, write_site
from siteline.tiles.reader import SceneTiles
from siteline.tiles.writer import TileInput, write_tiles
from siteline.views.generate import NamedCamera, generate_views
from siteline.views.ground import fit_ground_plane
from siteline.views.params import ViewParams


@dataclass(frozen=True)
class TradeGrid:
    scales: tuple[float, ...] = (1.0, 0.5, 0.25, 0.125)
    point_sizes: tuple[int, ...] = (1, 3)
    lod_factors: tuple[float, ...] = (1.0, 2.0)
    radius_multipliers: tuple[float, ...] = (1.5, 2.5, 4.0)
    backends: tuple[str, ...] = ("pykdtree", "ckdtree")
    splats: tuple[str, ...] = ("fixed", "world")


# world splats fill gaps within this many pixels (the release default, siteline.pairs.params.PairParams)
FILL_PX = 2


# The grid at paper density (1000 points/m2): the preset scales, both point sizes, three LOD factors;
# one label radius and backend (the 3D label trade does not depend on density).
DENSE = TradeGrid(
    scales=(0.25, 0.125), lod_factors=(1.0, 1.41, 2.0), radius_multipliers=(2.5,), backends=("pykdtree",)
)
QUICK = TradeGrid(scales=(1.0, 0.25), lod_factors=(1.0,), radius_multipliers=(2.5,))
# fixed disks against world splats in the paper's regime: the synthetic photos are 1/8 of a Zenmuse
# L2 frame, so scale 1 renders the paper's 1/8 (660 x 495) and scale 2 its 1/4 (1320 x 990)
SPLATS = TradeGrid(
    scales=(2.0, 1.0), point_sizes=(1, 3), lod_factors=(1.0,), radius_multipliers=(2.5,), backends=("pykdtree",)
)


@dataclass
class Scene:
    xyz: np.ndarray  # (N, 3) float64 site-local
    cls: np.ndarray  # (N,) uint8 site classes
    truth: np.ndarray  # (N,) bool changed (towards the other scene)
    tiles: SceneTiles


def _load(site_dir: Path, epoch: dict, site: SiteSpec, truth_key: str, work: Path, name: str) -> Scene:
    """Site-local points, classes and truth of an epoch, and a tile store whose gps_time holds each
    point's index (so tile reads map back to the truth)."""
    las_path = site_dir / epoch["mission_dir"] / LAS_RELPATH
    las = laspy.read(las_path)
    xyz = np.c_[las.x, las.y, las.z] - np.asarray(site.origin)
    lut, _ = site.taxonomy.code_lut("las")
    cls = lut[np.asarray(las.classification)]
    cls = np.where(inside_fence(xyz[:, :2], site.fence), cls, site.taxonomy.ignore_id).astype(np.uint8)
    truth = np.load(site_dir / "truth" / epoch["name"] / f"{truth_key}.npy")
    las.gps_time = np.arange(len(xyz), dtype=np.float64)
    indexed = work / f"{name}.las"
    las.write(indexed)
    r = write_tiles(
        TileInput(indexed, site, pyproj.CRS(site.crs)),
        work / f"{name}.zarr",
        resources=TilingResources(workers=1),
    )
    return Scene(xyz, cls, truth, SceneTiles.open(r.uri))


def _measure(fn: Callable[[], Any]) -> tuple[Any, float, float]:
    tracemalloc.start()
    t = time.perf_counter()
    out = fn()
    sec = time.perf_counter() - t
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return out, sec, peak / 2**20


def pareto(costs: Sequence[float], values: Sequence[float]) -> list[int]:
    """Indices of settings no other setting beats on both cost (lower) and value (higher)."""
    idx = sorted(range(len(costs)), key=lambda i: (costs[i], -values[i]))
    front, best = [], -np.inf
    for i in idx:
        if values[i] > best:
            front.append(i)
            best = values[i]
    return front


def run_trade(
    out_dir: Path,
    density: float = 10.0,
    views: int = 8,
    seed: int = 0,
    grid: TradeGrid | None = None,
    progress: Callable[[str], None] | None = None,
) -> list[dict[str, Any]]:
    grid = grid or TradeGrid()
    out_dir = Path(out_dir)
    work = out_dir / "work"
    say = progress or (lambda msg: None)
    site_dir = work / "site"
    cfg = SynthConfig(epochs=2, density_pts_m2=density, seed=seed, snow_epochs=(), projection_error_epochs=())
    if not (site_dir / "truth" / "site.json").exists():
        say(f"generating a 2-epoch synthetic site at {density:g} points/m2")
        write_site(site_dir, cfg)
    doc = json.loads((site_dir / "truth" / "site.json").read_text())
    ring = load_fence_geojson(site_dir / "fence.geojson", cfg.origin)
    site = make_site_spec("trade", cfg.crs, cfg.origin, [*ring, ring[0]], default_taxonomy())
    ignored = site.taxonomy.ignored_lut()
    for p in work.glob("*.zarr"):
        import shutil

        shutil.rmtree(p)
    a = _load(site_dir, doc["epochs"][0], site, "changed_until_next", work, "t1")
    b = _load(site_dir, doc["epochs"][1], site, "changed_since_previous", work, "t2")
    spacing = max(median_spacing(a.xyz), median_spacing(b.xyz))
    say(f"{len(a.xyz):,} and {len(b.xyz):,} points, median spacing {spacing:.3f} m")

    rows3d, flags = [], {}
    for mult in grid.radius_multipliers:
        r = mult * spacing
        for backend in grid.backends:
            (fa, fb), sec, peak = _measure(
                lambda r=r, backend=backend: (
                    change_flags(a.xyz, a.cls, b.xyz, b.cls, r, ignored, Matching(backend)),
                    change_flags(b.xyz, b.cls, a.xyz, a.cls, r, ignored, Matching(backend)),
                )
            )
            flags[mult] = (fa, fb)
            live = np.r_[fa != IGNORED, fb != IGNORED]
            pred = np.r_[fa, fb][live] == CHANGED
            true = np.r_[a.truth, b.truth][live]
            s = scores(confusion(pred.astype(np.int64), true.astype(np.int64)))
            rows3d.append(
                {
                    "radius_multiplier": mult,
                    "radius_m": r,
                    "backend": backend,
                    "label_seconds": sec,
                    "label_points_per_s": (len(a.xyz) + len(b.xyz)) / sec,
                    "label_peak_mib": peak,
                    "accuracy_3d": s.oa,
                    "f1_3d": s.f1,
                }
            )
    say("3D labels measured")

    cams = [
        NamedCamera(c["name"], Camera.from_dict(c["camera"]))
        for c in json.loads((site_dir / "truth" / doc["epochs"][1]["name"] / "cameras.json").read_text())
    ]
    ground = b.xyz[b.cls == site.taxonomy.id_of("ground")]
    plane = fit_ground_plane(ground, seed=seed)
    vp = ViewParams(views=views, seed=seed, scale=0.25, min_coverage=0.3)
    view_set = generate_views(cams, plane, site.fence, TilePointSource(b.tiles, np.array([], np.uint8)), vp)
    say(f"{len(view_set.views)} views")

    for v in view_set.views:  # warm the tile caches so the first setting does not pay for them
        for sc in (a, b):
            sc.tiles.points_for_view(v.camera, 1.0, ("gps_time",), level=None)
    truth_flag = {}
    for sc, name in ((a, "t1"), (b, "t2")):
        t = np.where(sc.truth, CHANGED, UNCHANGED).astype(np.uint8)
        t[ignored[sc.cls]] = IGNORED
        truth_flag[name] = t
    rows = []
    settings = itertools.product(grid.scales, grid.point_sizes, grid.splats, grid.lod_factors, grid.radius_multipliers)
    for scale, ps, splat, lod, mult in settings:
        render = RenderSettings(scale=scale, point_size_px=ps, splat=splat, fill_px=FILL_PX if splat == "world" else 0)
        pred_flags = {"t1": flags[mult][0], "t2": flags[mult][1]}
        cm = np.zeros((2, 2), np.int64)
        cov, valid_share, filled, read, sec_total = [], [], [], 0, 0.0
        peak_total = 0.0
        for v in view_set.views:

            def one(v=v, render=render, lod=lod, pred_flags=pred_flags):  # noqa: ANN202
                outs = {}
                n_read = 0
                for sc, name in ((a, "t1"), (b, "t2")):
                    pts = sc.tiles.points_for_view(
                        v.camera, render.scale, ("gps_time",), lod_factor=lod,
                        point_size_px=render.point_size_px,
                    )  # fmt: skip
                    n_read += pts.stats.points_read
                    idx = pts.attributes["gps_time"].astype(np.int64)
                    outs[name] = render_points(
                        pts.xyz_m.astype(np.float32),
                        v.camera,
                        render,
                        {"pred": pred_flags[name][idx], "truth": truth_flag[name][idx]},
                        spacing_m=pts.spacing_m,
                    )
                return outs, n_read

            (outs, n_read), sec, peak = _measure(one)
            ra, rb = outs["t1"], outs["t2"]
            pm = pair_mask(ra.hit, ra.attributes["pred"], rb.hit, rb.attributes["pred"])
            tm = pair_mask(ra.hit, ra.attributes["truth"], rb.hit, rb.attributes["truth"])
            valid = (pm != 255) & (tm != 255)
            cm += confusion(torch_int(pm[valid]), torch_int(tm[valid]))
            cov.append(float((ra.hit & rb.hit).mean()))
            valid_share.append(float((pm != 255).mean()))
            filled.append(float((ra.filled | rb.filled).mean()) if ra.filled is not None else 0.0)
            read += n_read
            sec_total += sec
            peak_total = max(peak_total, peak)
        s = scores(cm)
        r3 = next(
            r for r in rows3d if r["radius_multiplier"] == mult and r["backend"] == "pykdtree"
        )
        rows.append(
            {
                "scale": scale,
                "point_size_px": ps,
                "splat": splat,
                "lod_factor": lod,
                "radius_multiplier": mult,
                "seconds_per_view": sec_total / len(view_set.views),
                "peak_mib": peak_total,
                "points_read_per_view": read / len(view_set.views),
                "coverage": float(np.mean(cov)),
                "coverage_median": float(np.median(cov)),
                "valid": float(np.mean(valid_share)),
                "filled": float(np.mean(filled)),
                "f1_2d": s.f1,
                "iou_2d": s.iou_changed,
                "accuracy_3d": r3["accuracy_3d"],
                "f1_3d": r3["f1_3d"],
            }
        )
    say("renders measured")
    write_outputs(
        out_dir,
        rows,
        rows3d,
        {
            "density_pts_m2": density,
            "views": len(view_set.views),
            "points": [len(a.xyz), len(b.xyz)],
            "spacing_m": spacing,
        },
    )
    return rows


def torch_int(x: np.ndarray) -> np.ndarray:
    return x.astype(np.int64)


def write_outputs(out_dir: Path, rows: list[dict], rows3d: list[dict], meta: dict) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    with open(out_dir / "trade.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    with open(out_dir / "labels3d.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows3d[0]))
        w.writeheader()
        w.writerows(rows3d)
    costs = [r["seconds_per_view"] for r in rows]
    front_f1 = set(pareto(costs, [r["f1_2d"] for r in rows]))
    front_cov = set(pareto(costs, [r["coverage"] for r in rows]))
    lines = [
        f"Synthetic site: {meta['points'][0]:,} / {meta['points'][1]:,} points ({meta['density_pts_m2']:g} points/m2, "
        f"median spacing {meta['spacing_m']:.3f} m), {meta['views']} views.",
        "",
        "| scale | point px | splats | LOD factor | radius x | s/view | points read/view | coverage | valid | filled | F1 2D | IoU 2D | acc 3D | Pareto |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for i, r in enumerate(rows):
        mark = ("F1" if i in front_f1 else "") + (" cov" if i in front_cov else "")
        lines.append(
            f"| {r['scale']:g} | {r['point_size_px']} | {r['splat']} | {r['lod_factor']:g} | {r['radius_multiplier']:g} | "
            f"{r['seconds_per_view']:.3f} | {r['points_read_per_view']:,.0f} | {r['coverage']:.1%} | {r['valid']:.1%} | "
            f"{r['filled']:.1%} | {r['f1_2d']:.3f} | {r['iou_2d']:.3f} | {r['accuracy_3d']:.4f} | {mark.strip()} |"
        )
    lines += [
        "",
        "| radius x | radius m | backend | label s | points/s | peak MiB | acc 3D | F1 3D |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows3d:
        lines.append(
            f"| {r['radius_multiplier']:g} | {r['radius_m']:.3f} | {r['backend']} | {r['label_seconds']:.2f} | "
            f"{r['label_points_per_s']:,.0f} | {r['label_peak_mib']:.0f} | {r['accuracy_3d']:.4f} | {r['f1_3d']:.3f} |"
        )
    (out_dir / "trade.md").write_text("\n".join(lines) + "\n")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    for key, front, name in (
        ("coverage", front_cov, "seconds_vs_coverage.png"),
        ("f1_2d", front_f1, "seconds_vs_f1.png"),
    ):
        fig, ax = plt.subplots(figsize=(7, 4.5))
        for (ps, splat), marker in (((1, "fixed"), "o"), ((3, "fixed"), "s"), ((1, "world"), "^"), ((3, "world"), "D")):
            sel = [r for r in rows if r["point_size_px"] == ps and r["splat"] == splat]
            if not sel:
                continue
            sc = ax.scatter(
                [r["seconds_per_view"] for r in sel],
                [r[key] for r in sel],
                c=[np.log2(r["scale"]) for r in sel],
                marker=marker,
                cmap="viridis",
                label=f"{ps} px {splat}",
                alpha=0.8,
            )
        f = sorted(front, key=lambda i: costs[i])
        ax.plot([costs[i] for i in f], [rows[i][key] for i in f], "r--", label="Pareto front")
        ax.set_xscale("log")
        ax.set_xlabel("seconds per view (both scenes)")
        ax.set_ylabel(key)
        fig.colorbar(sc, ax=ax, label="log2(scale)")
        ax.legend()
        fig.tight_layout()
        fig.savefig(out_dir / name, dpi=100)
        plt.close(fig)


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description="The speed/accuracy sweep behind the presets (quick grid).")
    ap.add_argument("--site-density", type=float, default=10.0, help="points per m2")
    ap.add_argument("--views", type=int, default=8)
    ap.add_argument("--out", type=Path, default=Path("trade"))
    ap.add_argument("--full", action="store_true", help="the whole grid (default: the quick one)")
    ap.add_argument("--dense", action="store_true", help="the paper-density grid (DENSE)")
    ap.add_argument("--splats", action="store_true", help="fixed disks against world splats at 1/8 and 1/4 (SPLATS)")
    a = ap.parse_args()
    g = TradeGrid() if a.full else SPLATS if a.splats else DENSE if a.dense else QUICK
    run_trade(a.out, a.site_density, a.views, 0, g, progress=print)
    print((a.out / "trade.md").read_text())
