"""The markdown of the UI's release and pair artifacts: what a person watching the service needs to see
of the data (images, why a version exists, sizes, coverage, valid fractions, where it lives)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from siteline.records.pairs import PairOutput
from siteline.records.release import ReleaseInfo


def _spread(values: Sequence[float]) -> str:
    if not values:
        return "-"
    return f"mean {sum(values) / len(values):.2f} (min {min(values):.2f}, max {max(values):.2f})"


def _sizes(items: Sequence[Mapping[str, Any]]) -> str:
    rendered = sorted({tuple(it["size_px"]) for it in items})
    padded = sorted({tuple(it["padded_px"]) for it in items})
    text = ", ".join(f"{w} x {h}" for w, h in rendered) + " px"
    if padded != rendered:
        text += " (stored padded to " + ", ".join(f"{w} x {h}" for w, h in padded) + ")"
    return text


def release_markdown(info: ReleaseInfo, doc: Mapping[str, Any], montage_url: str) -> str:
    """The release artifact: montage, why this version, where it is, sizes and figures, its pairs,
    label sets and class balance (``doc``: the release's manifest)."""
    items = doc.get("items", [])
    lineage = doc.get("lineage", {})
    params = lineage.get("parameters", {})
    derived = lineage.get("release_params", {}).get("derived", {})
    splits = {s: sum(1 for it in items if it["split"] == s) for s in ("train", "val", "test")}
    lines = [
        f"# Release {info.name} {info.version} ({info.status})",
        "",
        f"![montage of {info.name} {info.version}: t1 | t2 | mask (green unchanged, red changed, white ignore)]({montage_url})",
        "",
        "| figure | value |",
        "|---|---|",
        f"| why this version | {info.reason or lineage.get('version_reason', '-')} |",
        f"| where | `{info.root}` (`siteline release show {info.name} {info.version}`) |",
        f"| images | {len(items)} (" + ", ".join(f"{k} {v}" for k, v in splits.items()) + ") |",
        f"| image size | {_sizes(items) if items else '-'} |",
        f"| scale | {params.get('scale')} {('(' + derived['scale'] + ')') if 'scale' in derived else ''} |",
        f"| point size | {params.get('point_size_px')} px {('(' + derived['point_size_px'] + ')') if 'point_size_px' in derived else ''} |",
        f"| views per pair | {params.get('views')} asked, min coverage {params.get('min_coverage')}, min valid {params.get('min_valid')} |",
        f"| coverage | {_spread([it['coverage'] for it in items])} |",
        f"| valid fraction | {_spread([it['valid'] for it in items])} |",
        f"| change ratio | {_spread([it['change_ratio'] for it in items])} |",
        f"| manifest sha256 | `{info.manifest_sha256}` |",
        "",
        "## Pairs",
        "",
        "| pair | scenes | label sets (t1, t2) | views | radius m |",
        "|---|---|---|---|---|",
    ]
    for q in lineage.get("pairs", []):
        views = sum(1 for it in items if it["pair"] == q["id"])
        ls = q.get("label_sets", {})
        lines.append(f"| {q['id']} | {q['t1']} -> {q['t2']} | v{ls.get('t1')}, v{ls.get('t2')} | {views} | {q['radius_m']:.3f} |")
    lines += ["", "## Scenes and label sets", "", "| scene | captured | label set | source |", "|---|---|---|---|"]
    for sc in lineage.get("scenes", []):
        lines.append(f"| {sc['id']} | {sc['capture_time']} | v{sc['label_set_version']} | {sc['label_set_source']} |")
    balance = doc.get("stats", {}).get("class_balance", {})
    lines += ["", "## Class balance (pixels)", "", "| split | changed | unchanged | ignore |", "|---|---|---|---|"]
    lines += [f"| {k} | {v['changed']:,} | {v['unchanged']:,} | {v['ignore']:,} |" for k, v in balance.items()]
    return "\n".join(lines) + "\n"


def pair_markdown(out: PairOutput, samples_url: str, shown: int) -> str:
    """The pair artifact: its first views as t1 | t2 | mask, and a row per view."""
    counts = out.labels.get("counts", {})
    lines = [
        f"# Pair {out.pair_id}: scene {out.t1} -> scene {out.t2}",
        "",
        f"![pair {out.pair_id}: the first {shown} views, t1 | t2 | mask (green unchanged, red changed, white ignore)]({samples_url})",
        "",
        f"{len(out.views)} views, radius {out.radius_m:.3f} m, label sets v{out.versions.t1} -> v{out.versions.t2}, "
        f"outputs `{out.root}`" + (f", 3D labels {counts}" if counts else ""),
        "",
        "| view | strategy | coverage t1 / t2 | valid | change ratio |",
        "|---|---|---|---|---|",
    ]
    lines += [
        f"| {v.index} | {v.strategy} | {v.coverage_a:.2f} / {v.coverage_b:.2f} | {v.valid:.2f} | {v.change_ratio:.3f} |"
        for v in out.views
    ]
    return "\n".join(lines) + "\n"
