"""Legible images of a cloud without colour: a real LiDAR-only forest (lidR's Topography.laz, 0.9
points/m2, intensity, no RGB) and a later epoch with the trees of a 60 x 60 m block felled (its
vegetation removed, the ground kept), rendered from the pair's synthetic views (the release's own
settings) in each colour (intensity, elevation ramp, height above the ground on the ramp) with and
without eye-dome lighting (siteline.render.shading).

Two figures per variant, medians over the renders: trees vs ground d' (the luminance of pixels showing
vegetation, > 2 m above the ground, against ground pixels, < 0.5 m, in pooled standard deviations: how
far apart a person sees them) and the edge contrast (the mean luminance step across a depth step
> 5 %, a crown over the ground behind it, over the mean step between all neighbouring drawn pixels).
Shots (A | B | mask of the first view: intensity, the old default, and the height ramp, the new one)
go to ``--shots`` (docs/images by default).

    python bench/legible.py [--views 8] [--shots docs/images]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import laspy
import numpy as np
from PIL import Image

from siteline.catalog import open_catalog
from siteline.catalog.scenes import get_scene
from siteline.config import Settings, sqlite_url
from siteline.labelsets.store import open_labelled
from siteline.pairs.execute import pair_labels, pair_views, scene_ground
from siteline.pairs.plan import plan_pair
from siteline.pairs.render import LabelledPair, pair_mask
from siteline.progress import no_progress
from siteline.records.pairs import ColourPlan
from siteline.records.params.pairs import PairParams
from siteline.release.datasheet import colour_mask
from siteline.render.colour import resolve_colour
from siteline.render.shading import eye_dome
from siteline.render.zbuffer import render_points

ROOT = Path(__file__).resolve().parents[1]
FOREST = ROOT / "tests" / "data" / "real" / "topography.laz"
EXE = str(Path(sys.executable).with_name("siteline"))


def felled(src: Path, out: Path) -> Path:
    """``src`` 400 days later with the vegetation (every class but ground, 2) of a 60 x 60 m block
    south-west of the centre removed."""
    las = laspy.read(src)
    x, y = np.asarray(las.x), np.asarray(las.y)
    cx, cy = (x.min() + x.max()) / 2, (y.min() + y.max()) / 2
    block = (x > cx - 80) & (x < cx - 20) & (y > cy - 80) & (y < cy - 20)
    keep = ~(block & (np.asarray(las.classification) != 2))
    new = laspy.LasData(las.header)
    new.points = las.points[keep]
    new.gps_time = np.asarray(new.gps_time) + 400 * 86400.0
    new.header.creation_date = las.header.creation_date.replace(year=las.header.creation_date.year + 1)
    new.write(out)
    return out


def _cli(home: Path, *argv: str) -> None:
    env = {"SITELINE_HOME": str(home), "PATH": "/usr/bin:/bin"}
    r = subprocess.run([EXE, *argv], env=env, capture_output=True, text=True)
    if r.returncode:
        raise SystemExit(f"siteline {' '.join(argv)} failed: {r.stderr}")


def site(work: Path) -> Settings:
    home = work / "home"
    later = felled(FOREST, work / "felled.laz")
    _cli(home, "init")
    _cli(home, "site", "create", "forest", "--crs", "EPSG:2949", "--origin", "273500", "5274500", "800")
    for path in (FOREST, later):
        _cli(home, "ingest", str(path), "--site", "forest", "--overlap", "0.5", "0.3", "--altitude", "100")
    return Settings(home=home, database_url=sqlite_url(home / "catalog.sqlite"))


def _luminance(rgb: np.ndarray) -> np.ndarray:
    return rgb.astype(np.float64) @ np.array([0.2126, 0.7152, 0.0722])


def separability(rgb: np.ndarray, height: np.ndarray, hit: np.ndarray) -> float:
    """d' of luminance between pixels showing vegetation (> 2 m above the ground) and ground (< 0.5 m):
    how far apart a person sees trees and ground, in pooled standard deviations."""
    lum = _luminance(rgb)
    veg, gnd = lum[hit & (height > 2.0)], lum[hit & (height < 0.5)]
    if len(veg) < 50 or len(gnd) < 50:
        return float("nan")
    return float(abs(veg.mean() - gnd.mean()) / max(np.sqrt((veg.var() + gnd.var()) / 2), 1e-6))


def edge_contrast(rgb: np.ndarray, depth: np.ndarray) -> float:
    """Mean luminance step between neighbouring pixels across a depth step (> 5 %: a crown over the
    ground behind it) over the mean step between all neighbouring drawn pixels."""
    lum = _luminance(rgb)
    d = np.where(np.isfinite(depth) & (depth > 0), depth, np.nan)
    across, every = [], []
    for a, b, la, lb in ((d[:, 1:], d[:, :-1], lum[:, 1:], lum[:, :-1]), (d[1:], d[:-1], lum[1:], lum[:-1])):
        ok = np.isfinite(a) & np.isfinite(b)
        rel = np.abs(a - b) / np.maximum(np.minimum(a, b), 1e-6)
        step = np.abs(la - lb)
        across.append(step[ok & (rel > 0.05)])
        every.append(step[ok])
    a_, e_ = np.concatenate(across), np.concatenate(every)
    return float(a_.mean() / max(e_.mean(), 1e-6)) if len(a_) and len(e_) else float("nan")


VARIANTS = {
    f"{source}{' + EDL' if edl else ''}": (source, edl)
    for source in ("intensity", "elevation", "height")
    for edl in (False, True)
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--views", type=int, default=8)
    ap.add_argument("--shots", type=Path, default=ROOT / "docs" / "images")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="legible-") as d:
        settings = site(Path(d))
        # the release's own settings for this site (auto scale and point size), as `release build` resolves them
        _cli(
            settings.home,
            "release",
            "build",
            "--site",
            "forest",
            "--name",
            "forest-cd",
            "--views",
            str(args.views),
        )
        (built,) = settings.home.glob("releases/forest-cd/.drafts/*/manifest.json")
        params = PairParams.from_dict(json.loads(built.read_text())["lineage"]["parameters"])
        cat = open_catalog(settings)
        with cat.transaction() as s:
            plan = plan_pair(s, settings.store, 1, params, None)
        t1, t2 = (open_labelled(sc.tiles, sc.label_set) for sc in (plan.t1, plan.t2))
        labels = pair_labels(plan, t1, t2, settings.store, no_progress)
        pair = LabelledPair.with_labels(t1, t2, labels.uri)
        views = pair_views(plan, t1, t2, no_progress).views
        with cat.transaction() as s:
            stats = [get_scene(s, sc.id).statistics.scan.colour_stats for sc in (plan.t1, plan.t2)]
        auto = plan.colour
        ground = scene_ground(plan, t2).model
        scores: dict[str, dict[str, list[float]]] = {k: {"sep": [], "edge": []} for k in VARIANTS}
        shade_s: list[float] = []
        shots: dict[str, list[np.ndarray]] = {}
        settings_r = params.render_settings()
        for k, view in enumerate(views):
            read = {}
            for side, tiles in ((1, pair.t1), (2, pair.t2)):
                pts = tiles.points_for_view(view.camera, params.scale, attributes=("intensity", "change"),
                                            lod_factor=params.lod_factor, point_size_px=params.point_size_px)  # fmt: skip
                read[side] = (pts, pts.attributes.pop("intensity"), ground.height(pts.xyz_m))
            z = np.concatenate([read[s][0].xyz_m[:, 2] for s in (1, 2)])
            elevation = ColourPlan("elevation", *([tuple(np.percentile(z, (2, 98)))] * 2))
            for name, (source, edl) in VARIANTS.items():
                colour = elevation
                if source == "intensity":
                    colour = resolve_colour("intensity", (plan.t1.id, stats[0]), (plan.t2.id, stats[1]))
                elif source == "height":
                    colour = resolve_colour("height", (plan.t1.id, stats[0]), (plan.t2.id, stats[1]))
                out = []
                for side in (1, 2):
                    pts, intensity, height = read[side]
                    values = {"intensity": intensity, "height": height}.get(source)
                    rgb = colour.colours(side, pts.xyz_m, values)  # type: ignore[union-attr]
                    r = render_points(pts.xyz_m.astype(np.float32), view.camera, settings_r,
                                      {"rgb": rgb, "change": pts.attributes["change"], "height": height.astype(np.float32)},
                                      spacing_m=pts.spacing_m)  # fmt: skip
                    img = r.rgb
                    if edl:
                        t0 = time.perf_counter()
                        img = eye_dome(img, r.depth)
                        shade_s.append(time.perf_counter() - t0)
                    scores[name]["sep"].append(separability(img, r.attributes["height"], r.hit))
                    scores[name]["edge"].append(edge_contrast(img, r.depth))
                    out.append((img, r))
                if k == 0:
                    (a, ra), (b, rb) = out
                    mask = pair_mask(
                        ra.hit, ra.attributes["change"], rb.hit, rb.attributes["change"], params.one_side_hole
                    )
                    shots[name] = [a, b, colour_mask(mask)]
        cat.dispose()
    print(f"{len(views)} views of the forest pair (0.9 points/m2, no RGB) at {views[0].camera.width} x "
          f"{views[0].camera.height} px x {params.scale}; the release's choice: {auto.source}, shading {auto.shading}")  # fmt: skip
    for name, sc in scores.items():
        print(f"  {name:18s} trees vs ground d' {np.nanmedian(sc['sep']):.2f}, edge contrast "
              f"{np.nanmedian(sc['edge']):.2f} (medians of {len(sc['sep'])} renders)")  # fmt: skip
    print(f"  eye-dome lighting: {1000 * np.median(shade_s):.1f} ms a render (numpy)")
    args.shots.mkdir(parents=True, exist_ok=True)
    for name, stem in (("intensity", "forest-intensity"), ("height", "forest-height")):
        Image.fromarray(np.concatenate(shots[name], axis=1)).save(args.shots / f"{stem}.png")
        print(f"  {args.shots / f'{stem}.png'}: {name} (A | B | mask of the first view)")


if __name__ == "__main__":
    main()
