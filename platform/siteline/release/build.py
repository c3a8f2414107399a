"""Building a draft release from its plan and the pairs' outputs (the execute part of a build; never
touches the catalog): format-2 images, statistics, montage, datasheet and manifest, written into
``releases/<name>/.drafts/<version>/`` whole (a draft may be rebuilt; published versions live
elsewhere) (DESIGN.md §8)."""

from __future__ import annotations

import io
import json
import logging
from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
from PIL import Image

from siteline import __version__
from siteline.errors import ReleaseError
from siteline.progress import Progress, no_progress
from siteline.records.pairs import PairOutput
from siteline.records.release import (
    FORMAT,
    DraftRelease,
    Lineage,
    ManifestDoc,
    PairLineage,
    ReleaseItem,
    ReleaseRecord,
    ReleaseStats,
    ViewsLineage,
)
from siteline.release import datasheet, layout
from siteline.release.manifest import METRIC_DEFINITION, file_entries, write_manifest
from siteline.release.plan import ReleasePlan
from siteline.release.splits import assign_splits
from siteline.stores import join, open_store, publish_folder
from siteline.stores.base import store_relative

log = logging.getLogger(__name__)
# an A or B image with fewer non-black pixels than this share of its pixels is blank: its points carry
# no colour (all-zero RGB, a constant intensity), and such a release is refused at build
BLANK_SHARE = 0.01


def read_png(uri: str) -> np.ndarray:
    """A pair output PNG from the store as an array (RGB (H, W, 3) or mask (H, W) uint8)."""
    return np.asarray(Image.open(io.BytesIO(open_store(uri).read_bytes(uri))))


def blank_sides(a: np.ndarray, b: np.ndarray) -> list[str]:
    """Which of a view's (H, W, 3) uint8 A and B images are blank (under BLANK_SHARE non-black)."""
    return [side for side, img in (("A", a), ("B", b)) if img.any(axis=-1).mean() < BLANK_SHARE]


def _refuse_blank(blank: Mapping[int, int], outputs: Mapping[int, PairOutput]) -> None:
    """:class:`ReleaseError` naming the pairs with blank A or B images (pair id -> views)."""
    if blank:
        worst = ", ".join(
            f"pair {pid}: {n} of {len(outputs[pid].views)} views (colour from {outputs[pid].colour.source})"
            for pid, n in sorted(blank.items())
        )
        raise ReleaseError(
            f"blank images: an A or B image with under {BLANK_SHARE:.0%} non-black pixels ({worst}); the "
            "points carry no colour there. Build with --colour intensity or --colour elevation (or auto, "
            "which takes them when a scene has no RGB). Nothing was written."
        )


def _write_items(
    plan: ReleasePlan, outputs: Mapping[int, PairOutput], split_of: Mapping[tuple[int, int], str], work: Path,
    progress: Progress,
) -> list[ReleaseItem]:  # fmt: skip
    """Every view of every pair as a release item: its five images in ``work/<split>/<folder>/``;
    :class:`ReleaseError` when any A or B image is blank (the caller's draft folder is then dropped)."""
    items = []
    blank: dict[int, int] = {}
    pad = plan.params.pad
    total = sum(len(o.views) for o in outputs.values())
    for pid in sorted(outputs):
        out = outputs[pid]
        for v in out.views:
            item_id = f"{plan.site_name}_p{pid:04d}_v{v.index:04d}"
            split = split_of.get((pid, v.index))
            if split is None:  # left out: a train view on ground a val or test view shows
                progress("release images", 1, total)
                continue
            rendered = {sub: read_png(join(out.root, sub, v.file)) for sub in ("A", "B", "label")}
            if blank_sides(rendered["A"], rendered["B"]):
                blank[pid] = blank.get(pid, 0) + 1
            arrays = layout.item_images(rendered["A"], rendered["B"], rendered["label"], pad)
            for sub, arr in arrays.items():
                dest = work / split / sub / f"{item_id}.png"
                dest.parent.mkdir(parents=True, exist_ok=True)
                Image.fromarray(arr).save(dest, format="PNG")
            h, w = rendered["label"].shape
            ph, pw = arrays["label"].shape
            items.append(
                ReleaseItem(
                    item_id, split, pid, v.index, v.strategy, min(v.coverage_a, v.coverage_b),  # type: ignore[arg-type]
                    v.change_ratio, v.valid, (int(w), int(h)), (int(pw), int(ph)), dict(v.ignore), v.filled,
                    v.camera.to_dict(), v.change_visible,
                )
            )  # fmt: skip
            progress("release images", 1, total)
    _refuse_blank(blank, outputs)
    return items


def _pair_lineage(o: PairOutput, store_url: str) -> PairLineage:
    views: ViewsLineage = {"made": len(o.views), "asked": o.params.views}
    if o.drawn:
        views.update(o.drawn.to_dict())
    doc: PairLineage = {
        "id": o.pair_id, "t1": o.t1, "t2": o.t2, "radius_m": o.radius_m, "label_sets": o.versions.to_dict(),
        "labels": o.labels.to_dict() | {"uri": store_relative(o.labels.uri, store_url)}, "colour_source": o.colour.source,
        "colour": o.colour.to_dict(), "fence": o.fence, "change_rule": o.change_rule.to_dict(),
    }  # fmt: skip
    if o.ground:
        doc["ground"] = o.ground.to_dict()
    doc["views"] = views
    return doc


def _lineage(plan: ReleasePlan, outputs: Mapping[int, PairOutput]) -> Lineage:
    params = plan.params
    pairs = [_pair_lineage(outputs[pid], plan.store_url) for pid in sorted(outputs)]
    return {
        "sites": [plan.site_lineage],
        "scenes": list(plan.scenes),
        "pairs": pairs,
        "parameters": params.pair.to_dict(),
        "preset": params.preset,
        "release_params": params.to_dict(),
        "seeds": {"views": params.pair.seed, "splits": params.pair.seed},
        "version_reason": plan.reason,
    }


def catalog_parameters(
    plan: ReleasePlan, outputs: Mapping[int, PairOutput], stats: ReleaseStats, left_out: list[list[int]]
) -> ReleaseRecord:
    """What the catalog records of a release (``release.parameters``): its parameters, the smallest
    change each pair resolves (its change radius, metres), where its ignore pixels come from
    (``release show``: ``stats``) and the items ``left_out`` of every split."""
    params = plan.params
    pairs = sorted(outputs)
    return {
        "pair_params": params.pair.to_dict(),
        "preset": params.preset,
        "release_params": params.to_dict(),
        "lineage_key": plan.lineage_key,
        "pairs": pairs,
        "label_sets": plan.lineage_key.get("label_sets", {}),
        "output_digests": plan.output_digests,
        "version_reason": plan.reason,
        "smallest_change_m": {str(pid): outputs[pid].radius_m for pid in pairs},
        "radius_ceiling_m": params.radius_ceiling_m,
        "ignore": stats["ignore"],
        "left_out": left_out,
        "changes_seen": {
            str(pid): d.changes.to_dict()
            for pid in pairs
            if (d := outputs[pid].drawn) and d.changes is not None
        },
    }


def execute_build(
    plan: ReleasePlan, outputs: Mapping[int, PairOutput], progress: Progress = no_progress
) -> DraftRelease:
    """Write the draft of ``plan`` from the pairs' ``outputs`` (pair id -> its outputs, every pair of the
    plan), replacing an earlier draft of the same version."""
    missing = [p.pair_id for p in plan.pairs if p.pair_id not in outputs]
    if missing:
        raise ReleaseError(f"pair {missing[0]} has no outputs to build release {plan.name} from.")
    split_plan = assign_splits(
        {pid: outputs[pid].views for pid in sorted(outputs)}, plan.params.pair.seed, plan.earlier_splits
    )
    splits = split_plan.pairs()
    with publish_folder(plan.draft) as work:
        items = _write_items(plan, outputs, split_plan.of, work, progress)
        rows = [it.to_dict() for it in items]
        stats = datasheet.statistics(work, list(items))
        (work / "stats.json").write_text(json.dumps(stats, indent=1) + "\n")
        datasheet.montage(work, [it for it in items if it.valid > 0.2] or list(items)).save(
            work / "montage.png"
        )
        doc: ManifestDoc = {
            "format": FORMAT, "layout": layout.layout_record(plan.params.pad), "name": plan.name,
            "version": plan.version, "created": datetime.now(UTC).isoformat(), "code_version": __version__,
            "files": [], "lineage": _lineage(plan, outputs), "splits": splits, "split_rule": split_plan.rule,
            "items": rows,
            "metric": METRIC_DEFINITION, "stats": stats,
        }  # fmt: skip
        (work / "README.md").write_text(datasheet.datasheet(doc, stats))
        doc["files"] = file_entries(work)
        manifest_sha = write_manifest(work, doc)
    log.info(
        "release %s %s: draft of %d items from %d pairs at %s",
        plan.name,
        plan.version,
        len(items),
        len(outputs),
        plan.draft,
    )
    return DraftRelease(
        plan.name, plan.version, str(plan.draft), manifest_sha, tuple(items), stats,
        catalog_parameters(plan, outputs, stats, [list(i) for i in sorted(split_plan.left_out)]),
        {pid: o.digest for pid, o in outputs.items()},
    )  # fmt: skip
