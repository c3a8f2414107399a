"""The markdown of the UI's release and pair artifacts: what a person watching the service needs to see
of the data (images, why a version exists, sizes, coverage, valid fractions, where it lives)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime
from urllib.parse import quote

from siteline.records.enums import SPLITS
from siteline.records.pairs import PairOutput, PairVersions
from siteline.records.params.pairs import PairParams
from siteline.records.release import Manifest, ReleaseInfo, ReleaseItem
from siteline.schema import JSON, json_object


@dataclass(frozen=True)
class RunEvent:
    """A state a service run entered: when (UTC), its name (Crashed, AwaitingRetry...), its message
    and the run's attempt count then."""

    when: datetime
    state: str
    message: str
    run_count: int


def _derived(derived: Mapping[str, JSON], knob: str) -> str:
    """``(why)`` where the release worked ``knob`` out for itself (its ``derived`` reasons), else nothing."""
    return f"({derived[knob]})" if knob in derived else ""


def _spread(values: Sequence[float]) -> str:
    if not values:
        return "-"
    return f"mean {sum(values) / len(values):.2f} (min {min(values):.2f}, max {max(values):.2f})"


def _sizes(items: Sequence[ReleaseItem]) -> str:
    rendered = sorted({tuple(it.size_px) for it in items})
    padded = sorted({tuple(it.padded_px) for it in items})
    text = ", ".join(f"{w} x {h}" for w, h in rendered) + " px"
    if padded != rendered:
        text += " (stored padded to " + ", ".join(f"{w} x {h}" for w, h in padded) + ")"
    return text


def release_markdown(
    info: ReleaseInfo, doc: Manifest, montage_url: str, preview_url: str | None = None
) -> str:
    """The release artifact: montage, links to its browser and each pair in 3D on the preview server
    at ``preview_url`` (None: none), why this version, where it is, sizes and figures, its pairs,
    label sets and class balance (``doc``: the release's manifest)."""
    items = doc.items
    lineage = doc.lineage
    params = PairParams.from_record(lineage["parameters"])
    derived = json_object(lineage["release_params"].get("derived") or {}, "derived")
    splits = {s: sum(1 for it in items if it.split == s) for s in SPLITS}
    lines = [
        f"# Release {info.name} {info.version} ({info.status})",
        "",
        f"![montage of {info.name} {info.version}: t1 | t2 | mask (green unchanged, red changed, white ignore)]({montage_url})",
        "",
        *_see_links(info, doc, preview_url),
        "| figure | value |",
        "|---|---|",
        f"| why this version | {info.reason or lineage.get('version_reason', '-')} |",
        f"| where | `{info.root}` (`siteline release show {info.name} {info.version}`) |",
        f"| images | {len(items)} (" + ", ".join(f"{k} {v}" for k, v in splits.items()) + ") |",
        f"| image size | {_sizes(items) if items else '-'} |",
        f"| scale | {params.scale} {_derived(derived, 'scale')} |",
        f"| point size | {params.point_size_px} px {_derived(derived, 'point_size_px')} |",
        f"| views per pair | {params.views} asked, min coverage {params.min_coverage}, min valid {params.min_valid} |",
        f"| coverage | {_spread([it.coverage for it in items])} |",
        f"| valid fraction | {_spread([it.valid for it in items])} |",
        f"| change ratio | {_spread([it.change_ratio for it in items])} |",
        f"| manifest sha256 | `{info.manifest_sha256}` |",
        "",
        "## Pairs",
        "",
        "| pair | scenes | label sets (t1, t2) | views | radius m |",
        "|---|---|---|---|---|",
    ]
    for q in lineage["pairs"]:
        views = sum(1 for it in items if it.pair == q["id"])
        ls = PairVersions.from_dict(q.get("label_sets"))
        lines.append(
            f"| {q['id']} | {q['t1']} -> {q['t2']} | v{ls.t1}, v{ls.t2} | {views} | {q['radius_m']:.3f} |"
        )
    lines += [
        "",
        "## Scenes and label sets",
        "",
        "| scene | captured | label set | source |",
        "|---|---|---|---|",
    ]
    for sc in lineage["scenes"]:
        lines.append(
            f"| {sc['id']} | {sc['capture_time']} | v{sc.get('label_set_version', 1)} | {sc.get('label_set_source')} |"
        )
    balance = doc.stats.get("class_balance", {})
    lines += [
        "",
        "## Class balance (pixels)",
        "",
        "| split | changed | unchanged | ignore |",
        "|---|---|---|---|",
    ]
    lines += [
        f"| {k} | {v['changed']:,} | {v['unchanged']:,} | {v['ignore']:,} |" for k, v in balance.items()
    ]
    return "\n".join(lines) + "\n"


def _see_links(info: ReleaseInfo, doc: Manifest, preview_url: str | None) -> list[str]:
    """Links to the release browser and to each pair in 3D (``siteline previews serve``)."""
    if not preview_url:
        return []
    base = f"{preview_url.rstrip('/')}"
    release = f"{quote(info.name)}/{quote(info.version)}"
    pairs = " ".join(f"[pair {q['id']}]({base}/3d/{release}/{q['id']}/)" for q in doc.lineage["pairs"])
    return [
        f"**See it:** [browse every item]({base}/browse/{release}/) (A | B swipe, mask, filters) · in 3D, change in red: {pairs}",
        "",
    ]


def stopped_markdown(
    run_name: str, events: Sequence[RunEvent], progress: str | None, max_attempts: int
) -> str:
    """Why a run stopped, in words, for its own page: each crash (when, what the state says: for
    a dead process or machine, its missing heartbeats), whether it was rescheduled and which attempt
    comes next, and how far the progress bar had come (``progress``: its description)."""
    crashes = [e for e in events if e.state == "Crashed"]
    last = crashes[-1] if crashes else events[-1]
    retried = any(e.state == "AwaitingRetry" and e.when >= last.when for e in events)
    attempt = max(e.run_count for e in events)
    lines = [
        f"# Why {run_name} stopped",
        "",
        f"At {last.when:%H:%M:%S} UTC ({last.when:%Y-%m-%d}) the run stopped: **{last.message or last.state}**.",
    ]
    if "heartbeat" in (last.message or ""):
        lines.append(
            "The process running it stopped reporting: it was killed, ran out of memory, or its machine "
            "went down. Nothing it had finished is lost."
        )
    if retried:
        lines.append(
            f"It was rescheduled (attempt {attempt + 1} of {max_attempts}): a worker picks it up again, and the "
            "pipeline reuses every finished output (tiles, labels, views, renders), so the retry redoes only "
            "what this attempt had not finished."
        )
    elif attempt >= max_attempts:
        lines.append(
            f"It crashed {attempt} times, the most the service retries: run it again by hand once the cause is fixed."
        )
    if progress:
        lines.append(f"Where it was: {progress}.")
    lines += ["", "| time (UTC) | state | attempt | message |", "|---|---|---|---|"]
    lines += [f"| {e.when:%H:%M:%S} | {e.state} | {e.run_count} | {e.message or '-'} |" for e in events]
    return "\n".join(lines) + "\n"


def pair_markdown(out: PairOutput, samples_url: str, shown: int) -> str:
    """The pair artifact: its first views as t1 | t2 | mask, and a row per view."""
    counts = {k: dict(v) for k, v in out.labels.counts.items()}
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
