"""The release's datasheet (README.md), statistics (stats.json) and montage (montage.png)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

MASK_COLOURS = {0: (40, 170, 60), 1: (220, 40, 40), 255: (255, 255, 255)}


def colour_mask(mask: np.ndarray) -> np.ndarray:
    """Green unchanged, red changed, white ignore (DESIGN.md §4)."""
    out = np.zeros(mask.shape + (3,), np.uint8)
    for v, c in MASK_COLOURS.items():
        out[mask == v] = c
    return out


def montage(root: Path, items: list[dict[str, Any]], count: int = 6, width: int = 1200) -> Image.Image:
    """Rows of (t1, t2, mask) for ``count`` sample items, ``width`` pixels wide."""
    rows = []
    for it in items[:count]:
        a = np.asarray(Image.open(root / it["split"] / "A" / f"{it['id']}.png").convert("RGB"))
        b = np.asarray(Image.open(root / it["split"] / "B" / f"{it['id']}.png").convert("RGB"))
        m = colour_mask(np.asarray(Image.open(root / it["split"] / "label" / f"{it['id']}.png")))
        rows.append(np.concatenate([a, b, m], axis=1))
    grid = np.concatenate(rows, axis=0) if rows else np.zeros((10, 30, 3), np.uint8)
    img = Image.fromarray(grid)
    return img.resize((width, max(1, int(img.height * width / img.width))), Image.NEAREST)


def statistics(root: Path, items: list[dict[str, Any]]) -> dict[str, Any]:
    """Pixel class balance per split, coverage and per-pair change ratio."""
    per_split: dict[str, dict[str, int]] = {}
    per_pair: dict[int, list[float]] = {}
    for it in items:
        m = np.asarray(Image.open(root / it["split"] / "label" / f"{it['id']}.png"))
        s = per_split.setdefault(it["split"], {"unchanged": 0, "changed": 0, "ignore": 0, "images": 0})
        s["unchanged"] += int((m == 0).sum())
        s["changed"] += int((m == 1).sum())
        s["ignore"] += int((m == 255).sum())
        s["images"] += 1
        per_pair.setdefault(it["pair"], []).append(it["change_ratio"])
    cov = [it["coverage"] for it in items]
    return {
        "class_balance": per_split,
        "coverage": {"mean": float(np.mean(cov)) if cov else 0.0, "min": float(np.min(cov)) if cov else 0.0},
        "per_pair_change_ratio": {str(k): float(np.mean(v)) for k, v in sorted(per_pair.items())},
        "images": len(items),
    }


def datasheet(doc: dict[str, Any], stats: dict[str, Any]) -> str:
    """README.md of a release: what it is, where it comes from, how it was made, how to use it."""
    lin = doc["lineage"]
    p = lin["parameters"]
    lines = [
        f"# {doc['name']} {doc['version']}",
        "",
        "A bi-temporal change-detection dataset rendered by siteline from drone LiDAR scenes of a construction site, "
        "following the iVISION-2DCD method: pixel-aligned image pairs from synthetic cameras and symmetric change masks.",
        "",
        "![samples: t1, t2, mask (green unchanged, red changed, white ignore)](montage.png)",
        "",
        "## Layout (LEVIR-CD / Open-CD style)",
        "",
        "`<split>/A/<id>.png` (t1), `<split>/B/<id>.png` (t2), `<split>/label/<id>.png` (0 unchanged, 1 changed, "
        "255 ignore: no point rendered or an ignored class). `manifest.json` lists every file with its size and sha256, "
        "the lineage and the splits; `stats.json` holds the figures below.",
        "",
        "## Sources",
        "",
        f"- sites: {', '.join(s['name'] + ' (' + s['crs'] + ')' for s in lin['sites'])}",
        f"- scenes: {', '.join(str(s['id']) + ' @ ' + s['capture_time'][:10] for s in lin['scenes'])}",
        "- pairs: "
        + ", ".join(f"{q['id']} ({q['t1']}->{q['t2']}, r={q['radius_m']:.3f} m)" for q in lin["pairs"]),
        "",
        "## Parameters",
        "",
        f"- preset: {lin.get('preset') or 'none'}",
        f"- render scale {p['scale']}, point size {p['point_size_px']} px, level-of-detail factor {p['lod_factor']}",
        f"- views per pair {p['views']}, seed {p['seed']}, minimum coverage {p['min_coverage']}",
        f"- change radius: {'auto (' + str(p['radius_multiplier']) + ' x median spacing)' if p['radius_m'] is None else str(p['radius_m']) + ' m'}",
        "",
        "## Splits (disjoint by pair)",
        "",
    ]
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
    lines += [
        "",
        f"Mean coverage (both renders hit) {stats['coverage']['mean']:.2%}.",
        "",
        "## Use",
        "",
        "```python",
        "from siteline.data import ChangeDetectionDataset",
        f"ds = ChangeDetectionDataset('{'<this folder>'}', split='train')  # image (2, 3, H, W) float32, mask (1, H, W) int64",
        "```",
        "",
        "Metrics: one confusion matrix over the whole split, 255 excluded; IoU per class, mIoU (mean of unchanged and "
        "changed IoU), precision/recall/F1 of changed, OA, kappa (`siteline.metrics`).",
        "",
        f"Built by siteline {doc['code_version']} on {doc['created'][:10]}.",
        "",
    ]
    return "\n".join(lines)
