"""The release's datasheet (README.md), statistics (stats.json) and montage (montage.png)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

from siteline.codes import IGNORE_CAUSES, RELEASE_IGNORE_CAUSES
from siteline.labels.accuracy import accuracy_text
from siteline.records.pairs import REJECTED_WORDS, ChangeLabels, ChangeRulePlan, ColourPlan, Drawn, GroundUsed
from siteline.records.params.labels import REACH_MULTIPLIER, SURFACE_RULES
from siteline.records.params.pairs import PairParams
from siteline.records.params.release import ReleaseParams
from siteline.records.registration import Registration
from siteline.records.release import (
    ClassBalance,
    IgnoreBreakdown,
    IgnoreTally,
    Lineage,
    ManifestDoc,
    PairLineage,
    ReleaseItem,
    ReleaseStats,
)

MASK_COLOURS = {0: (40, 170, 60), 1: (220, 40, 40), 255: (255, 255, 255)}


def colour_mask(mask: np.ndarray) -> np.ndarray:
    """Green unchanged, red changed, white ignore (DESIGN.md §4)."""
    out = np.zeros(mask.shape + (3,), np.uint8)
    for v, c in MASK_COLOURS.items():
        out[mask == v] = c
    return out


def triplet_grid(triplets: list[tuple[np.ndarray, np.ndarray, np.ndarray]], width: int) -> Image.Image:
    """Rows of (t1 | t2 | coloured mask), one per triplet of (RGB, RGB, 0/1/255 mask), scaled to
    ``width`` pixels wide (nearest neighbour: pixels stay pixels)."""
    rows = [np.concatenate([a, b, colour_mask(m)], axis=1) for a, b, m in triplets]
    grid = np.concatenate(rows, axis=0) if rows else np.zeros((10, 30, 3), np.uint8)
    img = Image.fromarray(grid)
    return img.resize((width, max(1, int(img.height * width / img.width))), Image.Resampling.NEAREST)


def montage(root: Path, items: list[ReleaseItem], count: int = 6, width: int = 1200) -> Image.Image:
    """Rows of (t1, t2, mask) for ``count`` sample items of the release at ``root``."""

    def rgb(sub: str, it: ReleaseItem) -> np.ndarray:
        return np.asarray(Image.open(root / it.split / sub / f"{it.id}.png").convert("RGB"))

    return triplet_grid(
        [
            (
                rgb("A", it),
                rgb("B", it),
                np.asarray(Image.open(root / it.split / "label_ignore" / f"{it.id}.png")),
            )
            for it in items[:count]
        ],
        width,
    )


def _shares(px: dict[str, float], total: float) -> dict[str, float]:
    return {k: (v / total if total else 0.0) for k, v in px.items()}


def ignore_breakdown(items: list[ReleaseItem], ignored_px: dict[str, int]) -> IgnoreBreakdown:
    """Where a release's ignore pixels come from: per cause (siteline.codes.RELEASE_IGNORE_CAUSES) the
    share of all stored pixels and of the rendered ones, overall and per split, and the share of
    rendered pixels whose point came from the gap fill. ``items``: the manifest's items (their
    ``ignore`` shares of the rendered image, sizes, ``filled``); ``ignored_px``: per split, the ignore
    pixels counted in its ``label_ignore/`` images, so what no item accounts for (outputs made before
    causes were recorded) is ``unaccounted``."""

    def tally(rows: list[ReleaseItem], counted: int) -> IgnoreTally:
        rendered = sum(it.size_px[0] * it.size_px[1] for it in rows)
        stored = sum(it.padded_px[0] * it.padded_px[1] for it in rows)
        px = {c: sum(it.ignore.get(c, 0.0) * it.size_px[0] * it.size_px[1] for it in rows)
              for c in IGNORE_CAUSES}  # fmt: skip
        px["padding"] = float(stored - rendered)
        px["unaccounted"] = max(0.0, counted - sum(px.values()))
        filled = sum(it.filled * it.size_px[0] * it.size_px[1] for it in rows)
        return {
            "share": counted / stored if stored else 0.0,
            "share_of_rendered": (counted - px["padding"]) / rendered if rendered else 0.0,
            "causes": _shares(px, stored),
            "causes_of_rendered": _shares(
                {c: px[c] for c in RELEASE_IGNORE_CAUSES if c != "padding"}, rendered
            ),
            "filled_of_rendered": filled / rendered if rendered else 0.0,
        }

    splits = sorted({it.split for it in items})
    per_split: dict[str, IgnoreTally] = {
        sp: tally([it for it in items if it.split == sp], ignored_px.get(sp, 0)) for sp in splits
    }
    return {**tally(items, sum(ignored_px.values())), "per_split": per_split}


def statistics(root: Path, items: list[ReleaseItem]) -> ReleaseStats:
    """Pixel class balance per split (from ``label_ignore/``; padding counts as ignore), coverage,
    per-pair change ratio and where the ignore pixels come from (:func:`ignore_breakdown`)."""
    per_split: dict[str, ClassBalance] = {}
    per_pair: dict[int, list[float]] = {}
    for it in items:
        m = np.asarray(Image.open(root / it.split / "label_ignore" / f"{it.id}.png"))
        s = per_split.setdefault(it.split, {"unchanged": 0, "changed": 0, "ignore": 0, "images": 0})
        s["unchanged"] += int((m == 0).sum())
        s["changed"] += int((m == 1).sum())
        s["ignore"] += int((m == 255).sum())
        s["images"] += 1
        per_pair.setdefault(it.pair, []).append(it.change_ratio)
    cov = [it.coverage for it in items]
    return {
        "class_balance": per_split,
        "coverage": {"mean": float(np.mean(cov)) if cov else 0.0, "min": float(np.min(cov)) if cov else 0.0},
        "per_pair_change_ratio": {str(k): float(np.mean(v)) for k, v in sorted(per_pair.items())},
        "images": len(items),
        "ignore": ignore_breakdown(items, {k: v["ignore"] for k, v in per_split.items()}),
    }


def _radius_lines(pairs: list[PairLineage], ceiling: float, params: PairParams) -> list[str]:
    """One line per pair: its radius, the false change it implies on unchanged surfaces, what its
    rule measured against analytic truth (siteline.labels.accuracy) and, when it is above the
    release's radius ceiling (metres), that it is."""
    rule, regions = params.label_rule, params.min_region_points
    out = []
    for q in pairs:
        radius = ChangeLabels.from_dict(q["labels"]).radius
        fc = radius.expected_false_change if radius is not None else None
        spacing = (
            max(radius.median_spacing_m.values(), default=float("nan"))
            if radius is not None
            else float("nan")
        )
        measured = accuracy_text(
            rule, regions, params.trim_edges, spacing, params.surface_probe, params.unsure_edges,
            params.sparse_surfaces,
        )  # fmt: skip
        if fc and rule in SURFACE_RULES:
            out.append(
                f"  - pair {q['id']}: r = {q['radius_m']:.3f} m = {fc['multiplier']:.2f} x spacing; the nearest-"
                f"neighbour test flags {fc['per_direction']:.2%} of unchanged surfaces per direction (2^(-k^2)), and "
                f"the {rule} rule keeps only those off the other scene's local surface by more than its level of "
                "detection"
                + (
                    " (that surface as the other scan sampled it, within "
                    f"{REACH_MULTIPLIER:g} radii; a place it did not observe is ignored)"
                    if rule == "adaptive"
                    else ""
                )
                + f"; changed regions under {regions} points are taken back"
                + (f"; {measured}" if measured else "")
                + (f"; ABOVE the radius ceiling of {ceiling:.2f} m" if q["radius_m"] > ceiling else "")
            )
        elif fc:
            out.append(
                f"  - pair {q['id']}: r = {q['radius_m']:.3f} m = {fc['multiplier']:.2f} x spacing: expected false "
                f"change on unchanged surfaces {fc['per_direction']:.2%} per direction, {fc['union']:.2%} in the "
                f"mask (2^(-k^2) per direction); the smallest change it resolves is {q['radius_m']:.2f} m (a "
                "surface that moved less, or a new object nearer than that to an old surface, is unchanged)"
                + (f"; {measured}" if measured else "")
                + (f"; ABOVE the radius ceiling of {ceiling:.2f} m" if q["radius_m"] > ceiling else "")
            )
    return out


def _ignore_share(stats: ReleaseStats) -> float:
    s = stats["class_balance"].values()
    total = sum(v["unchanged"] + v["changed"] + v["ignore"] for v in s)
    return sum(v["ignore"] for v in s) / max(total, 1)


def _layout_lines(doc: ManifestDoc, stats: ReleaseStats) -> list[str]:
    padding = doc["layout"]["padding"]
    return [
        "## Layout (format 2: LEVIR-CD, with the ignore information beside it)",
        "",
        *[f"- `<split>/{k}/<id>.png`: {v}" for k, v in doc["layout"]["folders"].items()],
        "",
        "`manifest.json` lists every file with its size and sha256, the lineage and the splits; `stats.json` "
        "holds the figures below.",
        "",
        "### Which folder your tool should read",
        "",
        "- Every toolbox (Open-CD, TorchGeo, ChangeMamba, torchange, ChangeFormer/BIT) reads `label/` correctly "
        "with its stock settings: 255 is changed, everything else unchanged. **Scores computed on `label/` alone "
        "count the ignore pixels as unchanged** "
        f"({_ignore_share(stats):.1%} of the pixels here), which inflates accuracy and mIoU.",
        "- To honour ignore, read `label_ignore/` (0/1/255) with `ignore_index=255`, or mask with `ignore/`. "
        "`siteline release export NAME VERSION --profile TOOL --out DIR` lays the release out for one tool and "
        "prints the one setting that tool needs; `siteline release score` scores a folder of predictions against "
        "the ignore-aware truth.",
        *(
            [
                f"- Images are padded (right and bottom) to sides that are multiples of {padding['multiple_px']} "
                f"and at least {padding['min_side_px']} px: images and `label/` with 0, `ignore/` and "
                "`label_ignore/` with ignore. `items[].size_px` in the manifest is the rendered size."
            ]
            if padding["enabled"]
            else []
        ),
        "",
    ]


def _views_text(q: PairLineage) -> str:
    """How many views a pair gave of those asked, and why not more."""
    v = q["views"]
    text = f"- pair {q['id']}: {v['made']} views of the {v['asked']} asked"
    if (drawn := Drawn.from_dict(v)) is not None:
        rejected = ", ".join(f"{n} {REJECTED_WORDS.get(k, k)}" for k, n in sorted(drawn.rejected.items()))
        unprobed = drawn.candidates - sum(drawn.rejected.values()) - v["made"]
        text += f" from {drawn.candidates} candidates ({rejected or 'none rejected'}"
        text += f"; {unprobed} not needed)" if unprobed > 0 and v["made"] >= (v["asked"] or 0) else ")"
        if drawn.changes is not None:
            text += f"\n  - changes seen: {drawn.changes.summary()}"
    return text


def _camera_lines(lin: Lineage) -> list[str]:
    """Where each scene's cameras came from, and each pair's colour and fence."""
    regs = {s["id"]: Registration.from_dict(s.get("registration")) for s in lin["scenes"]}
    sources = {sid: r.source for sid, r in regs.items()}
    lines = ["- cameras: " + ", ".join(f"scene {sid} {src}" for sid, src in sorted(sources.items()))]
    for sid, r in regs.items():
        if r.survey is not None and r.survey.altitude_m:
            lines.append(
                f"  - scene {sid}: {r.images or 0} cameras planned over the {r.over or 'area'} at "
                f"{r.survey.altitude_m:g} m ({r.altitude_why or 'given'})"
            )
    if "planned" in sources.values():
        lines.append(
            "  (planned: no photos, so siteline planned survey cameras from the point cloud; views derive from "
            "them as from photo cameras)"
        )
    for sid, r in regs.items():
        if (a := r.alignment) is not None:
            lines.append(f"- scene {sid} co-registered onto scene {a.against_scene}: {a.summary()}")
    lines += [_views_text(q) for q in lin["pairs"] if q.get("views")]
    lines += [
        f"- pair {q['id']}: {ground.summary()}"
        for q in lin["pairs"]
        if (ground := GroundUsed.from_dict(q.get("ground")))
    ]
    lines += [_colour_text(q) for q in lin["pairs"]]
    return lines


def _colour_text(q: PairLineage) -> str:
    """A pair's colour, its fence and its change rule, in words."""
    colour = ColourPlan.from_dict(q["colour"])
    return (
        f"- pair {q['id']}: colour from {colour.source}"
        + (f" ({colour.why})" if colour.why else "")
        + (", shaded by eye-dome lighting (siteline.render.shading)" if colour.shading == "edl" else "")
        + f", views judged against the {q['fence']}"
        + _rule_text(ChangeRulePlan.from_dict(q["change_rule"]))
    )


def _rule_text(rule: ChangeRulePlan) -> str:
    """How a pair's change labels treat classes, and why."""
    text = f", change rule {rule.rule} ({rule.why})"
    if rule.differences:
        text += ": " + "; ".join(rule.differences)
    return text


def _splat_text(p: PairParams) -> str:
    """How points were drawn and gaps filled, in words."""
    if p.splat == "fixed":
        text = f"splats: fixed, every point a {p.point_size_px} px disk"
    else:
        text = (
            f"splats: sized by the world, a point's disk spans {p.splat_factor:g} x its spacing seen from "
            f"the camera (at least {p.point_size_px} px, at most {p.splat_max_px} px; "
            + (
                "where a disk reaches past its surface's edge, the surface behind is drawn instead)"
                if p.trim_edges
                else "an object's edge is drawn up to half a disk beyond where its surface ends)"
            )
        )
    fill = p.fill_px
    return text + (
        f"; gaps filled from the nearest point of the surface around them within {fill} px"
        if fill
        else "; no gap fill"
    )


_CAUSE_WORDS = {
    "no_surface": "no surface in either scene (sky, beyond the scan)",
    "gap": "a gap between points in one scene",
    "one_side": "a surface in one scene only (a hole in the other render)",
    "outside_fence": "a point outside the site fence",
    "not_observed": "a place the other scan did not observe (a wall it grazed, ground in a shadow)",
    "unsure_edge": "an object's edge, or the gaps between a sparse object's points (a pole's), closer than its points can place it, between a changed and an unchanged surface",
    "ignored_class": "a point of an ignored class (noise, snow, ignore)",
    "padding": "padding to the stored size",
    "unaccounted": "not accounted (outputs made before causes were recorded)",
}


def _ignore_lines(stats: ReleaseStats) -> list[str]:
    """Where the ignore pixels come from, a row per cause."""
    ig = stats.get("ignore")
    if not ig:
        return []
    rows = [
        f"| {_CAUSE_WORDS[c]} | {ig['causes'].get(c, 0.0):.2%} | "
        + (f"{ig['causes_of_rendered'][c]:.2%} |" if c in ig["causes_of_rendered"] else "- |")
        for c in _CAUSE_WORDS
        if ig["causes"].get(c, 0.0) > 0 or c in ("no_surface", "gap")
    ]
    return [
        "## Where the ignore pixels come from",
        "",
        f"Ignore is {ig['share']:.2%} of all stored pixels and {ig['share_of_rendered']:.2%} of the rendered "
        f"ones (padding aside). The gap fill gave {ig['filled_of_rendered']:.2%} of the rendered pixels the point of "
        "the surface around them. Each item of `manifest.json` carries its own shares (`items[].ignore`).",
        "",
        "| cause | of all pixels | of rendered pixels |",
        "|---|---|---|",
        *rows,
        "",
    ]


def _source_lines(lin: Lineage) -> list[str]:
    release = ReleaseParams.from_dict(lin["release_params"])
    p = release.pair
    radius = f"auto ({p.radius_multiplier} x median spacing)" if p.radius_m is None else f"{p.radius_m} m"
    lod = "none (every point rendered)" if p.all_points else f"LOD factor {p.lod_factor}"
    return [
        "## Sources",
        "",
        "- sites: "
        + ", ".join(
            f"{s['name']} ({s['crs']}"
            + (f", version {s['version']}: taxonomy {s['taxonomy']}" if "version" in s else "")
            + ")"
            for s in lin["sites"]
        ),
        "- scenes: "
        + ", ".join(
            f"{s['id']} @ {s['capture_time'][:10]} (label set {s.get('label_set_version', 1)})"
            for s in lin["scenes"]
        ),
        "- pairs: "
        + ", ".join(f"{q['id']} ({q['t1']}->{q['t2']}, r={q['radius_m']:.3f} m)" for q in lin["pairs"]),
        *_camera_lines(lin),
        "",
        "## Parameters",
        "",
        f"- preset: {release.preset or 'none'}",
        f"- render scale {p.scale}, point size {p.point_size_px} px, level-of-detail factor {p.lod_factor}",
        "- " + _splat_text(p),
        f"- views per pair {p.views}, seed {p.seed}, minimum coverage {p.min_coverage}, minimum valid "
        f"share {p.min_valid}",
        f"- change radius: {radius}",
        *_radius_lines(lin["pairs"], release.radius_ceiling_m, p),
        f"- change labels: the {p.label_rule} rule (siteline.labels.change)"
        + (
            f", points beyond {p.surface_probe:g} radii of their nearest neighbour probed against the other scene's "
            "surface"
            if p.label_rule in SURFACE_RULES and p.surface_probe
            else ""
        )
        + f", changed regions under {p.min_region_points} points taken back (siteline.labels.regions)"
        + (
            ", but for a sparse surface's changed samples (a pole's), kept whole where most of its samples changed"
            if p.sparse_surfaces and p.min_region_points > 1
            else ""
        ),
        "- mask rules: a pixel is ignore (255) where either render has no point or its nearest point is of an "
        "ignored class (snow, noise, outside the fence); a pixel changed in one render and a hole in the other is "
        f"**{p.one_side_hole}**; change is the union (OR) of the two directions"
        + (
            "; a pixel where the edge trim, or a hole between a surface's points"
            + (", or the gap between a sparse surface's samples (a pole's)" if p.sparse_surfaces else "")
            + ", shows a surface whose change differs from the nearer one that may lie there is ignore (unsure edge)."
            if p.unsure_edges and p.trim_edges and p.splat == "world"
            else "."
        ),
        f"- level of detail: {lod}",
        "",
    ]


def _split_lines(doc: ManifestDoc, stats: ReleaseStats) -> list[str]:
    rule = doc.get("split_rule") or {"rule": "whole pairs, seeded"}
    lines = ["## Splits", "", f"- rule: {rule['rule']}"]
    if "max_shared_footprint" in rule:
        lines.append(
            f"- the largest share of a val or test view's footprint that train views of the same pair also show: "
            f"{rule['max_shared_footprint']:.0%} (target {rule.get('target_shared_footprint', 0.5):.0%}); views left "
            f"out of every split for it: {rule.get('left_out', 0)} (they stay out in later versions)"
        )
    turned = {p: a for p, a in (rule.get("band_direction_deg") or {}).items() if a}
    if turned:
        lines.append(
            "- bands turned from the long axis so that val and test hold change: "
            + ", ".join(f"pair {p} by {a:g} degrees" for p, a in turned.items())
        )
    empty = [s for s, c in (rule.get("changed_share") or {}).items() if c == 0.0]
    if empty:
        lines.append(
            f"- no changed pixels in {', '.join(empty)}: the pairs there show no change where their views look"
        )
    lines.append("")
    for split in ("train", "val", "test"):
        s = stats["class_balance"].get(split)
        if s:
            valid = s["unchanged"] + s["changed"]
            lines.append(
                f"- {split}: pairs {doc['splits'][split]}, {s['images']} images, changed "
                f"{s['changed'] / max(valid, 1):.2%} of valid pixels, ignore {s['ignore'] / max(valid + s['ignore'], 1):.2%}"
            )
        else:
            lines.append(f"- {split}: pairs {doc['splits'][split]}, no images")
    return [*lines, "", f"Mean coverage (both renders hit) {stats['coverage']['mean']:.2%}.", ""]


def _use_lines(doc: ManifestDoc) -> list[str]:
    return [
        "## Use",
        "",
        "```python",
        "from siteline.data import ChangeDetectionDataset",
        "ds = ChangeDetectionDataset('<this folder>', split='train')  # image (2, 3, H, W) float32, mask (1, H, W) int64 0/1/255",
        "```",
        "",
        "Metrics, two conventions, each named where it is reported (`siteline evaluate`, `siteline release score`):",
        "",
        "- **split** (siteline's default): one confusion matrix over the whole split, 255 excluded; IoU per class, "
        "mIoU (mean of unchanged and changed IoU over the classes present in truth or prediction), "
        "precision/recall/F1 of changed, OA, kappa.",
        "- **per image** (the paper's table, Pylon's code): per-image IoU per class, NaN when the class is absent "
        "from the image's truth and prediction, nan-mean over images, mIoU the mean of the two classes. The two "
        "differ by a few mIoU points: compare numbers of one convention only.",
        "",
        f"Built by siteline {doc['code_version']} on {doc['created'][:10]}.",
        "",
    ]


def datasheet(doc: ManifestDoc, stats: ReleaseStats) -> str:
    """README.md of a release: what it is, where it comes from, how it was made, how to use it."""
    head = [
        f"# {doc['name']} {doc['version']}",
        "",
        "A bi-temporal change-detection dataset rendered by siteline from drone LiDAR scenes of a construction site, "
        "following the iVISION-2DCD method: pixel-aligned image pairs from synthetic cameras and symmetric change masks.",
        "",
        f"Version {doc['version']}: {doc['lineage'].get('version_reason', 'first version')} (semantic versioning for "
        "datasets: new items only is a minor version, an item changed or removed or a split, parameter or "
        "format changed a major one).",
        "",
        "![samples: t1, t2, mask (green unchanged, red changed, white ignore)](montage.png)",
        "",
    ]
    lines = (
        head
        + _layout_lines(doc, stats)
        + _source_lines(doc["lineage"])
        + _split_lines(doc, stats)
        + _ignore_lines(stats)
    )
    return "\n".join(lines + _use_lines(doc))
