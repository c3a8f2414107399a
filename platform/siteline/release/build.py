"""Building draft releases and publishing them (DESIGN.md §8).

A draft lives in ``releases/<name>/.drafts/<version>/`` and may be rebuilt; publishing verifies its
checksums and renames it to ``releases/<name>/<version>/`` (atomic on one file system), makes it
read-only and marks the catalog row published. A published version is never rewritten.
"""

from __future__ import annotations

import io
import os
import shutil
import stat
import uuid
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from siteline import __version__
from siteline.catalog import Catalog
from siteline.catalog.labelsets import label_set
from siteline.catalog.models import Mission, Pair, Release, ReleaseItem, Scene, Site
from siteline.catalog.pairs import pair_view_ids
from siteline.catalog.releases import (
    clear_release_items,
    find_release,
    get_release,
    list_releases,
    release_item_counts,
)
from siteline.catalog.scenes import list_pairs, list_scenes
from siteline.catalog.sites import get_site
from siteline.catalog.stages import completed
from siteline.config import Settings
from siteline.errors import ImmutableError, NotFoundError, ReleaseError
from siteline.pairs import PairOutput, PairParams, pair_output
from siteline.release import datasheet, layout
from siteline.release.manifest import (
    METRIC_DEFINITION,
    file_entries,
    read_manifest,
    verify_files,
    write_manifest,
)
from siteline.release.params import ReleaseParams
from siteline.release.splits import split_pairs
from siteline.stores import join, open_store


@dataclass
class ReleaseInfo:
    name: str
    version: str
    status: str
    root: str
    items: int
    manifest_sha256: str | None
    stats: dict[str, Any]


def releases_dir(settings: Settings) -> Path:
    return settings.home / "releases"


def draft_path(settings: Settings, name: str, version: str) -> Path:
    return releases_dir(settings) / name / ".drafts" / version


def published_path(settings: Settings, name: str, version: str) -> Path:
    return releases_dir(settings) / name / version


def _semver(v: str) -> tuple[int, int, int]:
    a, b, c = (int(x) for x in v.split("."))
    return a, b, c


def next_version(session, name: str, lineage_key: dict) -> str:  # noqa: ANN001
    """1.0.0 first; a major bump when pairs, label sets or label/split parameters change, else a
    minor one. A version recorded before label sets were versioned used version 1 of every scene."""
    rows = list_releases(session, name)
    if not rows:
        return "1.0.0"
    latest = max(rows, key=lambda r: _semver(r.version))
    major, minor, _ = _semver(latest.version)
    previous = dict((latest.parameters or {}).get("lineage_key") or {})
    previous.setdefault("label_sets", dict.fromkeys(lineage_key.get("label_sets", {}), 1))
    if previous != lineage_key:
        return f"{major + 1}.0.0"
    return f"{major}.{minor + 1}.0"


def used_label_sets(outputs: dict[int, PairOutput]) -> dict[str, int]:
    """Scene id (as text, a JSON key) -> the label-set version the pairs' outputs used; ReleaseError
    when two pairs used different versions of one scene."""
    used: dict[str, int] = {}
    for out in outputs.values():
        for sid, side in ((out.t1, "t1"), (out.t2, "t2")):
            v = out.label_sets[side]
            if used.setdefault(str(sid), v) != v:
                raise ReleaseError(
                    f"scene {sid} is labelled with version {used[str(sid)]} in one pair and {v} in pair "
                    f"{out.pair_id}: a release uses one label set per scene. Nothing was written."
                )
    return dict(sorted(used.items(), key=lambda kv: int(kv[0])))


def _lineage(session, site: Site, pair_rows: list[Pair], outputs: dict[int, Any]) -> dict[str, Any]:  # noqa: ANN001
    scene_ids = sorted({p.t1_scene_id for p in pair_rows} | {p.t2_scene_id for p in pair_rows})
    versions = used_label_sets(outputs)
    scenes = []
    for sid in scene_ids:
        sc = session.get(Scene, sid)
        mission = session.get(Mission, sc.mission_id)
        labels = label_set(session, sid, versions[str(sid)])
        scenes.append(
            {
                "id": sc.id,
                "capture_time": sc.capture_time.isoformat(),
                "mission_manifest_sha256": mission.manifest_sha256,
                "label_set_version": labels.version,
                "label_set_source": labels.source,
                "label_set_sha256": labels.source_sha256,
                "registration": sc.registration,
                "tile_checksum": (sc.statistics or {}).get("tiles", {}).get("checksum"),
            }
        )
    pairs = [
        {
            "id": p.id,
            "t1": p.t1_scene_id,
            "t2": p.t2_scene_id,
            "radius_m": outputs[p.id].radius_m,
            "label_sets": outputs[p.id].label_sets,
            "labels": outputs[p.id].labels,
        }
        for p in pair_rows
    ]
    return {
        "sites": [{"name": site.name, "crs": site.crs, "origin": list(site.origin), "fence_m": site.fence}],
        "scenes": scenes,
        "pairs": pairs,
    }


def choose_pairs(session, site_name: str, pair_ids: list[int] | None = None) -> list[int]:  # noqa: ANN001
    """The pairs a release of ``site_name`` draws on: ``pair_ids`` (checked to be the site's) or every
    pair of the site, ascending; :class:`ReleaseError` when the site cannot make a release."""
    site = get_site(session, site_name)
    all_pairs = {p.id: p for p in list_pairs(session, site)}
    if pair_ids:
        for pid in pair_ids:
            row = session.get(Pair, pid)
            if row is None:
                raise NotFoundError(f"no pair with id {pid}. Nothing was written.")
            if row.site_id != site.id:
                other = session.get(Site, row.site_id)
                raise ReleaseError(
                    f"pair {pid} belongs to site {other.name}, not {site_name}: a release draws on "
                    "one site's pairs. Nothing was written."
                )
        chosen = sorted(set(pair_ids))
    else:
        chosen = sorted(all_pairs)
    scenes = list_scenes(session, site)
    if len(scenes) < 2:
        raise ReleaseError(
            f"site {site_name} has {len(scenes)} scene(s); a release needs at least two "
            "(ingest another mission). Nothing was written."
        )
    if not chosen:
        raise ReleaseError(f"site {site_name} has no pairs. Nothing was written.")
    return chosen


def build_release(
    catalog: Catalog,
    settings: Settings,
    site_name: str,
    name: str,
    params: PairParams | None = None,
    pair_ids: list[int] | None = None,
    version: str | None = None,
    preset: str | None = None,
    run_id: str | None = None,
    pad: bool = True,
    outputs: dict[int, PairOutput] | None = None,
    label_sets: dict[int, int] | None = None,
) -> ReleaseInfo:
    """Assemble a draft release ``name`` from the site's processed pairs (or ``pair_ids``) in format 2
    (siteline.release.layout): A, B, label (LEVIR-CD 0/255), ignore and label_ignore (0/1/255) per
    item; ``pad`` pads every image to sides that are multiples of 32 and at least 256 pixels.

    ``preset`` is applied to ``params`` here (siteline.presets) and recorded. Every pair must already
    be processed with these parameters: :class:`ReleaseError` names the command otherwise
    (``siteline.pipeline.release`` tiles and processes what is missing, then calls this with the
    ``outputs`` it made, so they are not read from the store again). Each scene's newest label set
    is used unless ``label_sets`` (scene id -> version) pins one; the versions are recorded in the
    lineage and a change of any of them from the previous version of ``name`` bumps the major
    version."""
    params = params or PairParams()
    if preset is not None:
        from siteline.presets import preset_params

        params = preset_params(preset, params)
    started = datetime.now(UTC)
    with catalog.transaction() as s:
        chosen = choose_pairs(s, site_name, pair_ids)
    given = outputs or {}
    outputs = {
        pid: given.get(pid) or pair_output(catalog, settings, pid, params, run_id, label_sets)
        for pid in chosen
    }
    unprocessed = [pid for pid, out in outputs.items() if out is None]
    if unprocessed:
        raise ReleaseError(
            f"pair {unprocessed[0]} is not processed with these parameters and label sets "
            f"({len(unprocessed)} of {len(chosen)} pairs): run `siteline release build`, which processes "
            "pairs first. Nothing was written."
        )
    with catalog.transaction() as s:
        release_params = ReleaseParams(params, preset, pad)
        lineage_key = {
            "pairs": chosen,
            "params": params.to_dict(),
            "format": layout.FORMAT,
            "pad": pad,
            "label_sets": used_label_sets(outputs),
        }
        if version is None:
            version = next_version(s, name, lineage_key)
        existing = find_release(s, name, version)
        if existing is not None and existing.status == "published":
            raise ImmutableError(
                f"release {name} {version} is already published and is never rewritten: build another "
                "version. Nothing was written."
            )
    try:
        _semver(version)
    except ValueError as exc:
        raise ReleaseError(f"version {version!r} is not semantic (MAJOR.MINOR.PATCH).") from exc
    splits = split_pairs(chosen, params.seed)
    split_of = {pid: sp for sp, ids in splits.items() for pid in ids}
    final = draft_path(settings, name, version)
    tmp = final.with_name(f".{version}.partial-{uuid.uuid4().hex[:8]}")
    items = []
    try:
        for pid in chosen:
            out = outputs[pid]
            for v in out.views:
                item_id = f"{site_name}_p{pid:04d}_v{v['index']:04d}"
                sp = split_of[pid]
                rendered = {
                    sub: _read_png(join(out.root, sub, v["file"])) for sub in ("A", "B", "label")
                }
                arrays = layout.item_images(rendered["A"], rendered["B"], rendered["label"], pad)
                for sub, arr in arrays.items():
                    dest = tmp / sp / sub / f"{item_id}.png"
                    dest.parent.mkdir(parents=True, exist_ok=True)
                    Image.fromarray(arr).save(dest, format="PNG")
                h, w = rendered["label"].shape
                items.append(
                    {
                        "id": item_id,
                        "split": sp,
                        "pair": pid,
                        "view": v["index"],
                        "strategy": v["strategy"],
                        "coverage": min(v["coverage_a"], v["coverage_b"]),
                        "change_ratio": v["change_ratio"],
                        "valid": v["valid"],
                        "size_px": [int(w), int(h)],
                        "padded_px": [int(arrays["label"].shape[1]), int(arrays["label"].shape[0])],
                    }
                )
        stats = datasheet.statistics(tmp, items)
        (tmp / "stats.json").write_text(__import__("json").dumps(stats, indent=1) + "\n")
        datasheet.montage(tmp, [it for it in items if it["valid"] > 0.2] or items).save(tmp / "montage.png")
        with catalog.transaction() as s:
            site = get_site(s, site_name)
            pair_rows = [s.get(Pair, pid) for pid in chosen]
            lineage = _lineage(s, site, pair_rows, outputs) | {
                "parameters": params.to_dict(),
                "preset": preset,
                "release_params": release_params.to_dict(),
                "seeds": {"views": params.seed, "splits": params.seed},
            }
        doc = {
            "format": layout.FORMAT,
            "layout": layout.layout_record(pad),
            "name": name,
            "version": version,
            "created": datetime.now(UTC).isoformat(),
            "code_version": __version__,
            "files": [],
            "lineage": lineage,
            "splits": splits,
            "items": items,
            "metric": METRIC_DEFINITION,
            "stats": stats,
        }
        (tmp / "README.md").write_text(datasheet.datasheet(doc, stats))
        doc["files"] = file_entries(tmp)
        manifest_sha = write_manifest(tmp, doc)
        if final.exists():
            shutil.rmtree(final)  # a draft may be rebuilt; published versions live elsewhere
        final.parent.mkdir(parents=True, exist_ok=True)
        os.replace(tmp, final)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    _record_draft(
        catalog,
        name,
        version,
        release_params,
        lineage_key,
        final,
        manifest_sha,
        items,
        {pid: out.digest for pid, out in outputs.items()},
        started,
        run_id,
    )
    return ReleaseInfo(name, version, "draft", str(final), len(items), manifest_sha, stats)


def _read_png(uri: str) -> np.ndarray:
    """A pair output PNG from the store as an array (RGB (H, W, 3) or mask (H, W) uint8)."""
    return np.asarray(Image.open(io.BytesIO(open_store(uri).read_bytes(uri))))


def _record_draft(
    catalog: Catalog,
    name: str,
    version: str,
    release_params: ReleaseParams,
    lineage_key: dict,
    root: Path,
    manifest_sha: str,
    items: list[dict],
    digests: dict[int, str],
    started: datetime | None = None,
    run_id: str | None = None,
) -> None:
    """The draft's catalog rows; ``digests``: pair id -> the key of the outputs it drew on."""
    params, preset = release_params.pair, release_params.preset
    chosen = sorted(digests)
    with catalog.transaction() as s:
        rel = find_release(s, name, version)
        if rel is None:
            rel = Release(name=name, version=version)
            s.add(rel)
        rel.status = "draft"
        rel.parameters = {
            "pair_params": params.to_dict(),
            "preset": preset,
            "release_params": release_params.to_dict(),
            "lineage_key": lineage_key,
            "pairs": chosen,
            "label_sets": lineage_key["label_sets"],
        }
        rel.root_uri = str(root)
        rel.manifest_sha256 = manifest_sha
        s.flush()
        clear_release_items(s, rel.id)
        view_ids: dict[int, dict[int, int]] = {}
        for it in items:
            if it["pair"] not in view_ids:
                view_ids[it["pair"]] = pair_view_ids(s, it["pair"], digests[it["pair"]])
            s.add(
                ReleaseItem(
                    release_id=rel.id,
                    item_id=it["id"],
                    pair_id=it["pair"],
                    view_id=view_ids[it["pair"]].get(it["view"]),
                    split=it["split"],
                    coverage=it["coverage"],
                    change_ratio=it["change_ratio"],
                    files={sub: f"{it['split']}/{sub}/{it['id']}.png" for sub in layout.FOLDERS},
                )
            )
        s.add(
            completed(
                "build_release",
                f"release:{name}:{version}",
                {"pair_params": params.to_dict(), "preset": preset, "pairs": chosen},
                started or datetime.now(UTC),
                run_id,
            )
        )


def _read_only(root: Path) -> None:
    for p in root.rglob("*"):
        mode = p.stat().st_mode
        p.chmod(mode & ~(stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))


def publish_release(
    catalog: Catalog, settings: Settings, name: str, version: str, run_id: str | None = None
) -> ReleaseInfo:
    """Verify the draft's checksums, move it into place, make it read-only, mark it published."""
    with catalog.transaction() as s:
        rel = find_release(s, name, version)
        if rel is None:
            raise NotFoundError(f"no release {name} {version}; build it first (`siteline release build`).")
        if rel.status == "published":
            raise ImmutableError(
                f"release {name} {version} is already published: a published version is never rewritten."
            )
    draft = draft_path(settings, name, version)
    final = published_path(settings, name, version)
    problems = verify_files(draft)
    if problems:
        raise ReleaseError(
            f"draft {name} {version} does not match its manifest ({len(problems)} problems, e.g. "
            f"{problems[0]}): rebuild it."
        )
    if final.exists():
        raise ImmutableError(f"{final} already exists: a published version is never rewritten.")
    os.replace(draft, final)
    try:
        with catalog.transaction() as s:
            rel = get_release(s, name, version)
            rel.status = "published"
            rel.published_at = datetime.now(UTC)
            s.add(completed("publish_release", f"release:{name}:{version}", {}, rel.published_at, run_id))
            rel.root_uri = str(final)
            sha = rel.manifest_sha256
            items = sum(release_item_counts(s, rel.id).values())
    except BaseException:
        os.replace(final, draft)
        raise
    _read_only(final)
    stats = read_manifest(final).get("stats", {})
    return ReleaseInfo(name, version, "published", str(final), items, sha, stats)


def release_root(catalog: Catalog, name: str, version: str) -> tuple[Path, str]:
    with catalog.transaction() as s:
        rel = get_release(s, name, version)
        return Path(rel.root_uri), rel.status
