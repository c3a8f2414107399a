"""Planning a release build and a publish: what the catalog says before anything is read or written."""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from sqlalchemy.orm import Session

from siteline.catalog.labelsets import label_set_ref
from siteline.catalog.pairs import get_pair, list_pairs
from siteline.catalog.releases import earlier_item_splits, find_release, list_releases, refuse_superseded
from siteline.catalog.scenes import (
    get_scene,
    list_scenes,
    mission_of_scene,
    scene_cameras,
    site_survey,
)
from siteline.catalog.sites import get_site, site_of
from siteline.config import Settings
from siteline.errors import ImmutableError, NotFoundError, ReleaseError
from siteline.pairs.plan import PairPlan, pair_change_rule, plan_pair
from siteline.records.pairs import ChangeRulePlan
from siteline.records.params.pairs import PairParams
from siteline.records.params.release import ReleaseKnobs, ReleaseParams
from siteline.records.release import FORMAT, LineageKey, ReleaseOptions, SceneLineage, SiteLineage
from siteline.release.knobs import check_coverage, check_image_size, resolve
from siteline.stores import layout as paths

RELEASE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,127}")
SEMVER = re.compile(r"(0|[1-9][0-9]*)\.(0|[1-9][0-9]*)\.(0|[1-9][0-9]*)")


def check_release_name(name: str) -> str:
    """``name`` when it is a release name (letters, digits, '_', '.', '-'; no path, no newline)."""
    if not isinstance(name, str) or not RELEASE_NAME.fullmatch(name) or name in (".", ".."):
        raise ReleaseError(
            f"release name {name!r} must be letters, digits, '_', '.' and '-' (up to 128, starting with a letter "
            "or digit). Nothing was written."
        )
    return name


def semver(version: str) -> tuple[int, int, int]:
    """(major, minor, patch) of ``MAJOR.MINOR.PATCH`` (no leading zeros, nothing around it);
    ReleaseError otherwise."""
    m = SEMVER.fullmatch(version) if isinstance(version, str) else None
    if m is None:
        raise ReleaseError(
            f"version {version!r} is not semantic: MAJOR.MINOR.PATCH, numbers without leading zeros (e.g. 1.0.0)."
        )
    return int(m.group(1)), int(m.group(2)), int(m.group(3))


def _changes(previous: LineageKey, key: LineageKey) -> list[str]:
    """What differs between two lineage keys, in words."""
    out = []
    added = sorted(set(key["pairs"]) - set(previous.get("pairs", [])))
    dropped = sorted(set(previous.get("pairs", [])) - set(key["pairs"]))
    out += [f"pairs added: {', '.join(map(str, added))}"] if added else []
    out += [f"pairs dropped: {', '.join(map(str, dropped))}"] if dropped else []
    before = previous.get("label_sets", {})
    out += [
        f"scene {sid} label set v{before.get(sid, 1)} -> v{v}"
        for sid, v in key.get("label_sets", {}).items()
        if sid in before and before[sid] != v
    ]
    # a knob added since the previous version had the value it meant before it existed
    old_params = {**PairParams.BEFORE, **previous.get("params", {})}
    out += [
        f"{k} {old_params.get(k)!r} -> {v!r}"
        for k, v in key["params"].items()
        if k in old_params and old_params[k] != v
    ]
    if "format" in previous and previous["format"] != key["format"]:
        out.append(f"format {previous['format']!r} -> {key['format']!r}")
    if "pad" in previous and previous["pad"] != key["pad"]:
        out.append(f"pad {previous['pad']!r} -> {key['pad']!r}")
    return out or ["lineage changed"]


def _only_added(previous: LineageKey, key: LineageKey, old_digests: Mapping[str, str],
                digests: Mapping[str, str]) -> bool:  # fmt: skip
    """Whether ``key`` only adds pairs to ``previous``: every earlier pair kept with the same label
    sets and outputs, the same parameters, format and padding (its items are then unchanged, and
    keep their splits: siteline.release.splits)."""
    old_pairs, new_pairs = set(previous.get("pairs", [])), set(key["pairs"])
    if not old_pairs < new_pairs:
        return False
    if (previous.get("params"), previous.get("format"), previous.get("pad")) != (
        key["params"],
        key["format"],
        key["pad"],
    ):
        return False
    before = previous.get("label_sets", {})
    if any(key.get("label_sets", {}).get(sid) != v for sid, v in before.items()):
        return False
    return all(old_digests.get(str(p)) == digests.get(str(p)) for p in old_pairs)


def pair_cameras(session: Session, pair_ids: Sequence[int]) -> dict[int, PairCameras]:
    """Each pair's later scene, its camera count (views derive from them) and, without cameras, why."""
    out = {}
    for pid in pair_ids:
        scene = get_scene(session, get_pair(session, pid).t2_scene_id)
        count = len(scene_cameras(session, scene.id))
        out[pid] = PairCameras(scene.id, count, "" if count else scene.registration.note or "")
    return out


@dataclass(frozen=True)
class PairCameras:
    """What a pair's views derive from: its later scene, that scene's camera count, and why it has
    none when it has none (its registration's note)."""

    scene_id: int
    count: int
    note: str = ""


def refuse_pairs_without_cameras(cameras: Mapping[int, PairCameras], what: str) -> None:
    """Refuse ``what`` when a pair's later scene has no cameras to derive views from, naming the
    scene and why it has none."""
    for pid, cams in sorted(cameras.items()):
        if cams.count == 0:
            raise ReleaseError(
                f"{what}: pair {pid} gives no views: its later scene {cams.scene_id} has no cameras"
                + (f" ({cams.note})" if cams.note else "")
                + ". Ingest its mission with photos, or plan cameras over a fence that lies over its points "
                "(`siteline site update --fence`, `siteline ingest --plan-cameras --altitude`). Nothing was made."
            )


def check_view_count(
    cameras: Mapping[int, PairCameras], params: PairParams, what: str, views_auto: bool
) -> None:
    """Refuse ``what`` before any view is made when a pair's later scene has no cameras (naming the
    scene and why), or, unless the view count is auto (as many as the cameras give), when a pair's
    cameras cannot give ``params.views`` candidates at all (each camera gives at most heights x
    {original, mirrored} x forward steps), naming the most it could give and the ways past it."""
    refuse_pairs_without_cameras(cameras, what)
    spec = params.view_params_spec()
    per_camera = len(spec.vertical_fractions) * (2 if spec.mirror else 1) * len(spec.forward_fractions)
    for pid, cams in sorted(cameras.items()):
        n = cams.count
        most = n * per_camera
        if not views_auto and most < params.views:
            raise ReleaseError(
                f"{what}: pair {pid} can give at most {most} candidate views ({n} cameras x "
                f"{per_camera} each), fewer than --views {params.views}: lower --views, leave it auto (as many as "
                "the cameras give), or plan more cameras (`siteline ingest --plan-cameras` with a higher --overlap). "
                "Nothing was made."
            )


def next_version(
    session: Session, name: str, lineage_key: LineageKey, digests: Mapping[str, str]
) -> tuple[str, str, str | None]:
    """(version, why, up to date with) for a build of ``name``, by semantic versioning for datasets:
    1.0.0 first; a minor bump when it only adds items (pairs added, every earlier item unchanged and
    in its split); a major bump when an item changes or goes (a pair dropped or superseded, a label
    set, a parameter, the format or padding changed, or a pair's outputs remade: a re-tiled scene);
    and the latest version itself (third item) when its inputs (lineage key and the pairs' output
    digests) are these: nothing new to build. A version recorded before label sets were versioned
    used version 1 of every scene. (A metadata-only change, a patch, has no build: a build always
    writes the items.)"""
    rows = list_releases(session, name)
    if not rows:
        return "1.0.0", "first version", None
    latest = max(rows, key=lambda r: semver(r.version))
    major, minor, _ = semver(latest.version)
    recorded = latest.parameters or {}
    # a copy (the row's own document stays as stored); none recorded: nothing in common but format and padding
    previous: LineageKey = {**recorded["lineage_key"]} if recorded.get("lineage_key") else {
        "pairs": [], "params": {}, "format": lineage_key["format"], "pad": lineage_key["pad"]
    }  # fmt: skip
    previous.setdefault("label_sets", dict.fromkeys(lineage_key.get("label_sets", {}), 1))
    old_digests = dict(recorded.get("output_digests") or {})
    if previous != dict(lineage_key):
        why = "; ".join(_changes(previous, lineage_key))
        if _only_added(previous, lineage_key, old_digests, digests):
            return f"{major}.{minor + 1}.0", f"new items only ({why})", None
        return f"{major + 1}.0.0", why, None
    if old_digests == dict(digests):
        return latest.version, "up to date", latest.version
    remade = sorted(int(p) for p, d in digests.items() if old_digests.get(p) != d)
    return (
        f"{major + 1}.0.0",
        f"items changed: outputs remade for pairs {', '.join(map(str, remade))} (a scene re-tiled)",
        None,
    )


def choose_pairs(session: Session, site_name: str, pair_ids: Sequence[int] | None = None) -> list[int]:
    """The pairs a release of ``site_name`` draws on: ``pair_ids`` (checked to be the site's) or every
    pair of the site, ascending; :class:`ReleaseError` when the site cannot make a release."""
    site = get_site(session, site_name)
    if pair_ids:
        for pid in pair_ids:
            try:
                row = get_pair(session, pid)
            except NotFoundError as exc:
                raise NotFoundError(f"{exc} Nothing was written.") from exc
            if row.site_id != site.id:
                raise ReleaseError(
                    f"pair {pid} belongs to site {site_of(session, row.site_id).name}, not {site_name}: a "
                    "release draws on one site's pairs. Nothing was written."
                )
        chosen = sorted(set(pair_ids))
    else:
        chosen = sorted(p.id for p in list_pairs(session, site))
    scenes = list_scenes(session, site)
    if len(scenes) < 2:
        raise ReleaseError(
            f"site {site_name} has {len(scenes)} scene(s); a release needs at least two "
            "(ingest another mission). Nothing was written."
        )
    if not chosen:
        raise ReleaseError(f"site {site_name} has no pairs. Nothing was written.")
    return chosen


def choice_key(pair_ids: Sequence[int], params: ReleaseParams) -> LineageKey:
    """What of a build's lineage key (:func:`next_version`) its choice decides: the pairs, the pair
    parameters, the format and the padding (the label sets are known once the pairs are planned)."""
    return {"pairs": list(pair_ids), "params": params.pair.to_dict(), "format": FORMAT, "pad": params.pad}


def used_label_sets(pairs: Sequence[PairPlan]) -> dict[str, int]:
    """Scene id (as text, a JSON key) -> the label-set version the pairs use, by scene id."""
    used = {str(sc.id): sc.label_set.version for p in pairs for sc in (p.t1, p.t2)}
    return dict(sorted(used.items(), key=lambda kv: int(kv[0])))


def output_digests(pairs: Sequence[PairPlan]) -> dict[str, str]:
    """Pair id (as text, a JSON key) -> the digest of the outputs a release draws on."""
    return {str(p.pair_id): p.digest for p in pairs}


def scene_lineage(session: Session, pairs: Sequence[PairPlan]) -> list[SceneLineage]:
    """The lineage record of every scene the pairs join: capture time, mission, label set, registration
    and tile checksum."""
    out: list[SceneLineage] = []
    for sid in sorted({sc.id for p in pairs for sc in (p.t1, p.t2)}):
        scene = get_scene(session, sid)
        version = next(sc.label_set.version for p in pairs for sc in (p.t1, p.t2) if sc.id == sid)
        labels = label_set_ref(session, sid, version)
        tiling = scene.statistics.tiling
        out.append(
            {
                "id": scene.id, "capture_time": scene.capture_time.isoformat(),
                "mission_manifest_sha256": mission_of_scene(session, sid).manifest_sha256,
                "label_set_version": labels.version, "label_set_source": labels.source,
                "label_set_sha256": labels.source_sha256, "registration": scene.registration.to_dict(),
                "tile_checksum": tiling.checksum if tiling is not None else None,
                "las_software": scene.statistics.scan.generating_software if scene.statistics.scan else None,
            }
        )  # fmt: skip
    return out


@dataclass(frozen=True)
class ReleasePlan:
    """What building a draft release needs from the catalog: the site and its record for the lineage,
    the release's name and version (and the key that chose it), its parameters, each pair's plan
    (where its outputs are), the scenes' lineage, the draft's folder, and the splits of the latest
    earlier version's items (which this one keeps: siteline.release.splits), and the data store's
    root (the manifest records its addresses relative to it)."""

    site_name: str
    site_lineage: SiteLineage
    name: str
    version: str
    params: ReleaseParams
    pairs: tuple[PairPlan, ...]
    scenes: tuple[SceneLineage, ...]
    lineage_key: LineageKey
    draft: Path
    reason: str
    up_to_date: str | None
    earlier_splits: dict[tuple[int, int], str] = field(default_factory=dict)
    store_url: str = ""

    @property
    def output_digests(self) -> dict[str, str]:
        return output_digests(self.pairs)


@dataclass(frozen=True)
class ReleaseChoice:
    """What a release is made of, chosen once before any pair is processed: its pairs (ascending), its
    resolved parameters, and each pair's change rule (stated then, not found in the masks afterwards)."""

    pair_ids: tuple[int, ...]
    params: ReleaseParams
    rules: Mapping[int, ChangeRulePlan]


def choose_release(
    session: Session, site_name: str, name: str, knobs: ReleaseKnobs | None, options: ReleaseOptions
) -> ReleaseChoice:
    """The choice of release ``name`` of ``site_name`` (one transaction): its pairs (``options.pair_ids``
    or every pair of the site), refused when one has no cameras; its parameters (the site's release
    settings with ``knobs`` over them, refused when its images would be too small or the views asked
    cannot be had); each pair's change rule on the label sets ``options.label_sets`` pins."""
    check_release_name(name)
    if options.version is not None:
        semver(options.version)
    chosen = choose_pairs(session, site_name, options.pair_ids)
    cameras = pair_cameras(session, chosen)
    refuse_pairs_without_cameras(cameras, f"release {name}")
    params = release_params(session, site_name, knobs, f"release {name}")
    if options.version is not None:
        refuse_published_version(session, name, options.version, chosen, params)
    check_view_count(cameras, params.pair, f"release {name}", "views" in params.derived)
    rules = {
        pid: pair_change_rule(session, pid, params.pair.change_rule, options.label_sets) for pid in chosen
    }
    return ReleaseChoice(tuple(chosen), params, rules)


def refuse_published_version(
    session: Session, name: str, version: str, pair_ids: Sequence[int], params: ReleaseParams
) -> None:
    """Refuse, before any pair is processed, a build asked to be ``version`` of ``name`` when that
    version is published and the build cannot be it: the version is not the latest (only the latest
    is ever found up to date), or it was made of other pairs, parameters, format or padding. (Other
    label sets or remade outputs are found once the pairs are processed: :func:`plan_release`.)"""
    existing = find_release(session, name, version)
    if existing is None or existing.status != "published":
        return
    latest = max(list_releases(session, name), key=lambda r: semver(r.version))
    recorded = dict((existing.parameters or {}).get("lineage_key") or {})
    differs = [k for k, v in choice_key(pair_ids, params).items() if recorded.get(k) != v]
    if latest.version != version or differs:
        why = (
            f"{latest.version} is the latest" if latest.version != version else "other " + ", ".join(differs)
        )
        raise ImmutableError(
            f"release {name} {version} is already published and is never rewritten ({why}): build another "
            "version. Nothing was made."
        )


def plan_release(
    session: Session, settings: Settings, site_name: str, name: str, choice: ReleaseChoice,
    version: str | None = None, pinned: Mapping[int, int] | None = None,
) -> ReleasePlan:  # fmt: skip
    """The plan of building draft ``name`` of ``site_name`` from ``choice`` (:func:`choose_release`; one
    transaction). The version is the next one (:func:`next_version`; ``up_to_date`` names the latest
    version when its inputs are these) unless given; a published version is refused, and so are
    images under the size floor."""
    params, chosen = choice.params, list(choice.pair_ids)
    if version is not None:
        semver(version)
    pairs = tuple(plan_pair(session, settings.store, pid, params.pair, pinned) for pid in chosen)
    key = choice_key(chosen, params) | {"label_sets": used_label_sets(pairs)}
    digests = output_digests(pairs)
    auto, reason, up_to_date = next_version(session, name, key, digests)
    if version is not None and version != up_to_date:  # a given version is built as asked
        up_to_date, reason = None, reason if reason != "up to date" else f"version {version} given"
    version = version or auto
    if up_to_date is None:
        check_image_size(
            params, site_survey(session, get_site(session, site_name)), f"release {name} {version}"
        )
    existing = find_release(session, name, version)
    if up_to_date is None and existing is not None and existing.status == "published":
        raise ImmutableError(
            f"release {name} {version} is already published and is never rewritten: build another "
            "version. Nothing was written."
        )
    semver(version)
    spec = get_site(session, site_name).spec
    record: SiteLineage = {"name": spec.name, "crs": spec.crs, "origin": list(spec.origin),
              "fence_m": [list(v) for v in spec.fence] if spec.fence is not None else None,
              "version": spec.version, "taxonomy": spec.taxonomy.name}  # fmt: skip
    return ReleasePlan(
        site_name, record, name, version, params, pairs, tuple(scene_lineage(session, pairs)), key,
        paths.release_draft(settings.home, name, version), reason, up_to_date,
        earlier_item_splits(session, name, version), settings.store.url,
    )  # fmt: skip


def release_params(session: Session, site_name: str, knobs: ReleaseKnobs | None, what: str) -> ReleaseParams:
    """The parameters of a build of ``site_name``: the site's release settings with ``knobs`` (a
    command's) over them, auto knobs worked out from the site's cameras and density; refused when its
    images would be under the size floor."""
    site = get_site(session, site_name)
    survey = site_survey(session, site)
    params = resolve([site.release_settings, knobs or ReleaseKnobs()], survey)
    check_image_size(params, survey, what)
    check_coverage(params, survey, what)
    return params


@dataclass(frozen=True)
class PublishPlan:
    """Publishing a draft: its name and version, the draft's folder and the published one."""

    name: str
    version: str
    draft: Path
    final: Path
    manifest_sha256: str | None


def plan_publish(session: Session, settings: Settings, name: str, version: str) -> PublishPlan:
    """The plan of publishing draft ``name`` ``version``; refused when there is no such release, it is
    already published, or a pair it was built from has been superseded since (a middle scene ingested
    while it was built)."""
    check_release_name(name)
    semver(version)
    rel = find_release(session, name, version)
    if rel is None:
        raise NotFoundError(f"no release {name} {version}; build it first (`siteline release build`).")
    if rel.status == "published":
        raise ImmutableError(
            f"release {name} {version} is already published: a published version is never rewritten."
        )
    refuse_superseded(session, rel)
    return PublishPlan(
        name, version, paths.release_draft(settings.home, name, version),
        paths.release_published(settings.home, name, version), rel.manifest_sha256,
    )  # fmt: skip
