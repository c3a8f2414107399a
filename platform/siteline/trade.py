"""The speed/accuracy trade, measured against a truth the renderer did not draw.

A 2-epoch synthetic site (the construction site, the analytic box scene ``boxes`` or the sloped scene
``slope``, flown by the airborne scanner unless ``scan="sampled"``) is made, ingested
and run through the pipeline with its release defaults and with named variants of the pair knobs
(label radius, splats, gap fill, render scale, level of detail, ...); each variant's masks are scored
per pixel against the site's analytic surfaces ray-cast through the same cameras
(siteline.synth.scoring): precision, recall and F1 of changed, boundary F (2 px), each changed object's
recall, the false change on each object that stayed, false-change specks per view, the share of the
truth's pixels the mask ignores, seconds. ``siteline bench trade`` and ``bench/trade.py`` run it.
A variant that leaves no usable view is reported as such, not dropped.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from PIL import Image

from siteline import pipeline
from siteline.catalog import Catalog, migrate, open_catalog
from siteline.catalog.context import StageContext
from siteline.catalog.engine import make_engine
from siteline.catalog.pairs import pair_ids_of_scene
from siteline.catalog.scenes import get_scene, list_scenes, tile_source
from siteline.catalog.sites import add_site, get_site
from siteline.config import Settings, sqlite_url
from siteline.errors import ConfigError, PairError, SynthError
from siteline.pairs.sources import nearest_point
from siteline.records.params.pairs import PairParams
from siteline.records.params.release import ReleaseKnobs
from siteline.schema import JSON
from siteline.site.fence import load_fence_geojson
from siteline.site.spec import make_site_spec
from siteline.synth import SynthParams, write_site
from siteline.synth.scanner import SCANS
from siteline.synth.scoring import score_pair
from siteline.tiles.reader import SceneTiles

SITE = "trade"
LAYOUTS = ("site", "boxes", "slope")
# the sloped scene and the box scene are LiDAR-only scans (issue 67 sets them so: their cameras are
# planned from the scan, above the box scene's crane); the box scene had the synthetic photos' cameras
# before 2026-11-29 (docs/performance.md says which figures were measured so)
LIDAR_ONLY = ("slope", "boxes")
# named sets of variants (pair knobs over the release defaults: on the synthetic site, 3 px world
# splats at the auto scale 0.78 of its 660 x 495 photos). The photos are 1/8 of a Zenmuse L2 frame, so
# scale 1 renders the paper's 1/8 of a frame and scale 2 its 1/4.
GRIDS: dict[str, dict[str, dict[str, JSON]]] = {
    "quick": {"default": {}, "no gap fill": {"fill_px": 0}},
    "full": {
        "default": {},
        "radius x1.5": {"radius_multiplier": 1.5},
        "radius x4": {"radius_multiplier": 4.0},
        "fixed 1 px": {"splat": "fixed", "point_size_px": 1},
        "fixed 3 px": {"splat": "fixed", "point_size_px": 3},
        "no gap fill": {"fill_px": 0},
        "scale 1/8 frame": {"scale": 1.0},
        "scale 1/4 frame": {"scale": 2.0},
        "LOD x2": {"lod_factor": 2.0},
    },
}


@dataclass(frozen=True)
class TradeScene:
    """The synthetic scene a trade runs on: its ``layout`` (:data:`LAYOUTS`), LiDAR ``density`` (points
    per m2), ``scan`` (``flown`` or ``sampled``, siteline.synth.SynthParams), ``views`` a pair and
    ``seed``; refused with a ConfigError naming the value."""

    layout: str = "site"
    density: float = 10.0
    scan: str = "flown"
    views: int = 24
    seed: int = 0

    def __post_init__(self) -> None:
        if self.layout not in LAYOUTS:
            raise ConfigError(f"layout {self.layout!r}: use one of {', '.join(LAYOUTS)}.")
        if not (math.isfinite(self.density) and self.density > 0):
            raise ConfigError(f"site density {self.density!r} must be a positive number of points per m2.")
        if self.scan not in SCANS:
            raise ConfigError(f"scan {self.scan!r}: use one of {', '.join(SCANS)}.")

    def folder(self, out: Path) -> Path:
        """Where the scene and its tables are kept under ``out``: ``<layout>-<density>`` (``-sampled``
        added for sampled epochs)."""
        return Path(out) / (
            f"{self.layout}-{self.density:g}" + ("" if self.scan == "flown" else f"-{self.scan}")
        )


@dataclass(frozen=True)
class TradeRow:
    """One variant's measurement: its knobs, the pair's seconds (labels, views and renders) and the
    labels' alone, the change radius (metres) and the scores (siteline.synth.viewtruth.MaskScore's
    dict), or why it made no release (``error``)."""

    variant: str
    knobs: Mapping[str, JSON]
    seconds: float = math.nan
    label_seconds: float = math.nan
    radius_m: float = math.nan
    scores: Mapping[str, object] = field(default_factory=dict)
    error: str | None = None

    def to_dict(self) -> dict[str, object]:
        return {
            "variant": self.variant, "knobs": dict(self.knobs), "seconds": self.seconds,
            "label_seconds": self.label_seconds, "radius_m": self.radius_m, "error": self.error, **self.scores,
        }  # fmt: skip

    def line(self) -> str:
        """The row in one line of text."""
        if self.error:
            return f"{self.variant:>12}: no release: {self.error}"
        s = self.scores
        objects = ", ".join(f"{k} {v:.2f}" for k, v in dict(s["object_recall"]).items())  # type: ignore[call-overload]
        kept = ", ".join(f"{k} {v:.1%}" for k, v in dict(s.get("false_change", {})).items())  # type: ignore[call-overload]
        shown = ", ".join(f"{k} {v}" for k, v in dict(s.get("object_views", {})).items())  # type: ignore[call-overload]
        dropped = ", ".join(f"{k} {v:.1%}" for k, v in dict(s.get("object_ignored", {})).items())  # type: ignore[call-overload]
        through = ", ".join(f"{k} {v:.1%}" for k, v in dict(s.get("object_through", {})).items())  # type: ignore[call-overload]
        cams: dict[str, float] = dict(s.get("camera_nearest_m", {}))  # type: ignore[call-overload]
        return (
            f"{self.variant:>12}: P {s['precision']:.3f} R {s['recall']:.3f} F1 {s['f1']:.3f} boundary F "
            f"{s['boundary_f']:.3f} specks/view median {s['specks_median']:.0f} (max {s['specks_max']}), rim "
            f"pieces/view median {s['rims_median']:.0f} ({s.get('rim_px', '-')} of {dict(s['confusion'])['fp']} false-changed px "  # type: ignore[call-overload]
            f"within 2 px of a change), scored {s['scored_share']:.1%} of pixels, ignored "
            f"{_share(s.get('dropped_share'))} of the truth's, labels "
            f"{_seconds(self.label_seconds)}, pair {self.seconds:.0f} s; recall: {objects}; false change: {kept}; "
            f"views showing each changed object: {shown or '-'}; its pixels ignored: {dropped or '-'}; "
            f"labelled unchanged (see-through): {through or '-'}; nearest point to a camera: {_metres(cams)}; "
            f"cameras: {_planned(s.get('planned_altitude'))}"
        )


def _planned(value: object) -> str:
    """The later scene's planned survey altitude and why, or that its cameras were photos'."""
    if not isinstance(value, dict):
        return "photos (or not recorded)"
    return f"planned at {value['altitude_m']:g} m ({value['why']})"


def _share(value: object) -> str:
    """A share as a percentage, "-" for rows measured before it was (no such figure)."""
    return f"{value:.1%}" if isinstance(value, float) else "-"


def _metres(cams: Mapping[str, float]) -> str:
    """A camera-distance summary, "-" for rows measured before it was."""
    if not cams:
        return "-"

    def far(v: float) -> str:
        return f">= {CAMERA_REACH_M:g}" if v >= CAMERA_REACH_M else f"{v:.2f}"

    return f"min {far(cams['min'])} m, 10th pct {far(cams['p10'])} m, median {far(cams['median'])} m"


def _seconds(s: float) -> str:
    """Seconds, or "reused" for labels an earlier variant made (same radius and rule)."""
    return "reused" if math.isnan(s) else f"{s:.1f} s"


def parse_variant(text: str) -> tuple[str, dict[str, JSON]]:
    """``NAME=JSON`` (pair knobs over the defaults, e.g. ``r4={"radius_multiplier": 4}``)."""
    name, sep, knobs = text.partition("=")
    try:
        parsed = json.loads(knobs) if sep else None
    except ValueError as exc:
        raise ConfigError(f"variant {text!r}: the knobs after '=' are not JSON ({exc}).") from None
    if not name or not isinstance(parsed, dict):
        raise ConfigError(f'variant {text!r}: write NAME={{"knob": value, ...}}.')
    return name, parsed


def synthetic_pair(out: Path, scene: TradeScene) -> tuple[Settings, Path, int]:
    """A 2-epoch synthetic site of ``scene`` under ``out`` (made once: a later call reuses it), with
    photos unless its layout is LiDAR-only (:data:`LIDAR_ONLY`), its home with the site registered
    (``scene.views`` views a pair) and both epochs ingested; the settings, the site's folder and the
    pair's id."""
    photos = scene.layout not in LIDAR_ONLY
    try:
        cfg = SynthParams(
            epochs=2, density_pts_m2=scene.density, seed=scene.seed, snow_epochs=(), projection_error_epochs=(),
            layout=scene.layout, scan=scene.scan, photos=photos, colmap=photos,
        )  # fmt: skip
    except SynthError as exc:
        raise ConfigError(str(exc)) from None
    views, seed = scene.views, scene.seed
    site_dir = out / "site"
    if not (site_dir / "truth" / "site.json").exists():
        write_site(site_dir, cfg)
    home = out / "home"
    settings = Settings(home=home, database_url=sqlite_url(home / "catalog.sqlite"))
    made = (home / "catalog.sqlite").exists()
    home.mkdir(parents=True, exist_ok=True)
    engine = make_engine(settings.database_url)
    migrate.upgrade(engine)
    engine.dispose()
    cat = open_catalog(settings)
    try:
        if not made:
            ring = load_fence_geojson(site_dir / "fence.geojson", cfg.origin)
            with cat.transaction() as s:
                spec = make_site_spec(SITE, cfg.crs, cfg.origin, [*ring, ring[0]])
                add_site(s, spec, ReleaseKnobs(pair={"views": views, "seed": seed}))
        doc = json.loads((site_dir / "truth" / "site.json").read_text())
        for e in doc["epochs"]:
            pipeline.ingest(StageContext(cat, settings), site_dir / e["mission_dir"], SITE)
        with cat.transaction() as s:
            scenes = list_scenes(s, get_site(s, SITE))
            pid = pair_ids_of_scene(s, scenes[-1].id)[0]
    finally:
        cat.dispose()
    return settings, site_dir, pid


# a camera's nearest point is looked for within this distance (metres); none nearer reads as this
CAMERA_REACH_M = 20.0


def camera_clearance(scenes: Sequence[SceneTiles], centers: np.ndarray) -> np.ndarray:
    """(M,) metres from each camera centre (M, 3, site-local) to the nearest point of any of
    ``scenes`` at full density (every class), :data:`CAMERA_REACH_M` where none is nearer."""
    return np.minimum(nearest_point(scenes, centers, CAMERA_REACH_M, np.zeros(0, np.uint8)), CAMERA_REACH_M)


def variant_params(base: PairParams, name: str, knobs: Mapping[str, JSON]) -> PairParams:
    """``base`` with variant ``name``'s ``knobs`` over it; :class:`ConfigError` naming the variant for
    an unknown knob or a bad value."""
    unknown = sorted(set(knobs) - set(base.to_dict()))
    if unknown:
        raise ConfigError(
            f"variant {name!r}: unknown pair knobs {unknown}; see siteline.records.params.pairs.PairParams."
        )
    try:
        return PairParams.from_dict(base.to_dict() | dict(knobs))
    except (TypeError, ValueError, PairError) as exc:
        raise ConfigError(f"variant {name!r}: {exc}") from None


def measure_variant(
    cat: Catalog, settings: Settings, site_dir: Path, pid: int, name: str, knobs: Mapping[str, JSON],
    pictures: Callable[[str, int, np.ndarray, np.ndarray], None] | None = None,
) -> TradeRow:  # fmt: skip
    """Pair ``pid`` processed with ``knobs`` over the site's release defaults, scored against the
    analytic truth. ``pictures`` is given each view's index, mask and truth."""
    params = variant_params(pipeline.release_parameters(cat, SITE).pair, name, knobs)
    t = time.perf_counter()
    try:
        result = pipeline.process_pairs(StageContext(cat, settings), [pid], params)[pid]
    except PairError as exc:  # a setting that leaves no usable view is a finding
        return TradeRow(name, dict(knobs), error=str(exc))
    seconds = time.perf_counter() - t

    def keep(view, mask, truth) -> None:  # noqa: ANN001
        if pictures is not None:
            pictures(name, view.index, mask, truth.mask)

    score = score_pair(settings.store, result.root, site_dir, (0, 1), keep)
    with cat.transaction() as s:
        scenes = [SceneTiles.from_source(tile_source(s, sid)) for sid in (result.t1, result.t2)]
        later = get_scene(s, result.t2).registration
    planned = (
        {"altitude_m": later.survey.altitude_m, "why": later.altitude_why or "given"}
        if later.survey is not None and later.survey.altitude_m
        else None
    )
    near = camera_clearance(scenes, np.array([v.camera.center for v in result.views]))
    cameras = {
        "min": float(near.min()),
        "p10": float(np.percentile(near, 10)),
        "median": float(np.median(near)),
    }
    return TradeRow(
        name, dict(knobs), seconds, result.labels.seconds or math.nan, result.radius_m,
        score.to_dict() | {"camera_nearest_m": cameras, "planned_altitude": planned},
    )  # fmt: skip


def run_trade(
    out: Path, scene: TradeScene | None = None, variants: Mapping[str, Mapping[str, JSON]] | None = None,
    progress: Callable[[str], None] = print, pictures: int = 0,
) -> list[TradeRow]:  # fmt: skip
    """Every variant (name -> pair knobs; the full grid when None) measured on the synthetic ``scene``
    (the construction site flown at 10 points/m2 when None) kept under ``scene.folder(out)``; writes
    trade.json and trade.md there (and ``pictures`` mask | truth | disagreement images a variant) and
    returns the rows."""
    scene = scene if scene is not None else TradeScene()
    variants = variants if variants is not None else GRIDS["full"]
    for name, knobs in variants.items():  # refused before anything is made
        variant_params(PairParams(), name, knobs)
    folder = scene.folder(out)
    folder.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    settings, site_dir, pid = synthetic_pair(folder, scene)
    progress(
        f"synthetic {scene.layout} ({scene.scan}) at {scene.density:g} points/m2 ingested "
        f"({time.perf_counter() - t0:.0f} s)"
    )
    saved: dict[str, int] = {}

    def picture(name: str, index: int, mask: np.ndarray, truth: np.ndarray) -> None:
        if saved.get(name, 0) < pictures:
            save_disagreement(
                folder / f"{name.replace(' ', '_').replace('/', '-')}-{index:04d}.png", mask, truth
            )
            saved[name] = saved.get(name, 0) + 1

    rows = []
    cat = open_catalog(settings)
    try:
        for name, knobs in variants.items():
            rows.append(measure_variant(cat, settings, site_dir, pid, name, knobs, picture))
            progress(rows[-1].line())
    finally:
        cat.dispose()
    (folder / "trade.json").write_text(json.dumps([r.to_dict() for r in rows], indent=1) + "\n")
    (folder / "trade.md").write_text(trade_markdown(rows, scene.layout, scene.density, scene.scan))
    return rows


def trade_markdown(rows: list[TradeRow], layout: str, density: float, scan: str = "flown") -> str:
    """The rows as a Markdown table (the least-scoring changed object's recall and the most falsely
    changed object that stayed beside the totals; a variant's pair seconds leave out labels it reused)."""
    measured = [r for r in rows if not r.error and "planned_altitude" in r.scores]
    cameras = (
        f"The later scene's cameras: {_planned(measured[0].scores['planned_altitude'])}.\n\n"
        if measured
        else ""
    )
    head = (
        f"Trade on the synthetic {layout} ({scan}) at {density:g} points/m2, against the analytic truth\n\n"
        + cameras
        + "| variant | knobs | precision | recall | F1 | boundary F | specks / view | lowest object recall "
        "| most false change | ignored of truth | scored | fewest views of a changed object | most see-through "
        "| nearest camera m | pair s | labels s |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for r in rows:
        knobs = ", ".join(f"{k}={v}" for k, v in r.knobs.items()) or "release defaults"
        if r.error:
            lines.append(
                f"| {r.variant} | {knobs} | no release: {r.error} |  |  |  |  |  |  |  |  |  |  |  |  |  |"
            )
            continue
        s = r.scores
        objects: dict[str, float] = dict(s["object_recall"])  # type: ignore[call-overload]
        low = min(objects.items(), key=lambda kv: kv[1]) if objects else ("-", math.nan)
        kept: dict[str, float] = dict(s.get("false_change", {}))  # type: ignore[call-overload]
        worst = "-" if not kept else "{} {:.1%}".format(*max(kept.items(), key=lambda kv: kv[1]))
        shown: dict[str, int] = dict(s.get("object_views", {}))  # type: ignore[call-overload]
        fewest = "-" if not shown else "{} {}".format(*min(shown.items(), key=lambda kv: kv[1]))
        through: dict[str, float] = dict(s.get("object_through", {}))  # type: ignore[call-overload]
        most = "-" if not through else "{} {:.1%}".format(*max(through.items(), key=lambda kv: kv[1]))
        cams: dict[str, float] = dict(s.get("camera_nearest_m", {}))  # type: ignore[call-overload]
        nearest = f"{cams['min']:.2f}" if cams else "-"
        lines.append(
            f"| {r.variant} | {knobs} | {s['precision']:.3f} | {s['recall']:.3f} | {s['f1']:.3f} | "
            f"{s['boundary_f']:.3f} | {s['specks_median']:.0f} | {low[0]} {low[1]:.2f} | {worst} | "
            f"{_share(s.get('dropped_share'))} | {s['scored_share']:.1%} | {fewest} | {most} | {nearest} | "
            f"{r.seconds:.0f} | {_seconds(r.label_seconds)} |"
        )
    return head + "\n".join(lines) + "\n"


def save_disagreement(path: Path, mask: np.ndarray, truth: np.ndarray) -> None:
    """mask | truth | disagreement as one PNG (red: false changed, blue: missed, grey: ignored by either)."""
    colours = {0: (40, 140, 60), 1: (220, 40, 40), 255: (235, 235, 235)}

    def paint(m: np.ndarray) -> np.ndarray:
        img = np.zeros((*m.shape, 3), np.uint8)
        for v, c in colours.items():
            img[m == v] = c
        return img

    diff = np.full((*mask.shape, 3), 255, np.uint8)
    both = (mask != 255) & (truth != 255)
    diff[~both] = (200, 200, 200)
    diff[both & (mask == 1) & (truth == 0)] = (220, 30, 30)
    diff[both & (mask == 0) & (truth == 1)] = (30, 60, 220)
    diff[both & (mask == 1) & (truth == 1)] = (30, 30, 30)
    gap = np.full((mask.shape[0], 4, 3), 255, np.uint8)
    Image.fromarray(np.concatenate([paint(mask), gap, paint(truth), gap, diff], axis=1)).save(path)
