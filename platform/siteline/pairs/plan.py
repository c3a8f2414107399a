"""Planning a pair: what the catalog says about a pair and its two scenes before anything is read."""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass

from sqlalchemy.orm import Session

from siteline.camera.pinhole import Camera
from siteline.catalog.labelsets import label_set, label_set_ref, newest_versions
from siteline.catalog.pairs import get_pair, pair_view_ids
from siteline.catalog.scenes import get_scene, scene_cameras, tile_source
from siteline.catalog.sites import site_of
from siteline.errors import PairError
from siteline.labels.rule import resolve_change_rule
from siteline.records.labelsets import LabelSetRef
from siteline.records.pairs import ChangeRulePlan, ColourPlan, PairVersions
from siteline.records.params.pairs import PairParams
from siteline.records.tiling import TileSource
from siteline.render.colour import resolve_colour
from siteline.site.spec import SiteSpec
from siteline.stores import Store, layout


def output_digest(
    params: PairParams, versions: tuple[int, int], tilings: tuple[int, int] = (0, 0), rule: str = "semantic",
    look: str = "none",
) -> str:  # fmt: skip
    """The key of a pair's outputs: the parameters' digest, extended by the label-set versions when
    either is not 1, by the scenes' tiling generations when either was re-tiled and by the change
    rule when it is ``geometry`` (so outputs made before each was recorded keep their key, a
    re-tiled scene never reuses outputs aligned with its old tile order, and an ``auto`` rule that
    resolves to geometry never reuses semantic labels), and by the look of the images when they are
    shaded or coloured by height (``look``: ColourPlan.look, e.g. ``edl:height``; an ``auto`` colour or shading that
    resolves to them never reuses the intensity images made before)."""
    if tuple(versions) == (1, 1) and tuple(tilings) == (0, 0) and rule == "semantic" and look == "none":
        return params.digest()
    text = f"{params.digest()}:labels:{versions[0]}:{versions[1]}"
    if tuple(tilings) != (0, 0):
        text += f":tiles:{tilings[0]}:{tilings[1]}"
    if rule != "semantic":
        text += f":rule:{rule}"
    if look != "none":
        text += f":shading:{look}"  # the key's words as first written
    return hashlib.sha256(text.encode()).hexdigest()[:12]


@dataclass(frozen=True)
class PairScene:
    """One scene of a pair as the pair reads it: its id, its tiles, the label set whose classes it
    uses, and its tiling generation (0 until re-tiled)."""

    id: int
    tiles: TileSource
    label_set: LabelSetRef
    generation: int


@dataclass(frozen=True)
class PairPlan:
    """Everything processing a pair needs from the catalog: the pair, its site, both scenes, the later
    scene's cameras (photo or planned; views are derived from them), the parameters, where the
    outputs go (keyed by :func:`output_digest`), whether the catalog already records them, and the
    fence views are judged against (``fence``: the site's, else the later scene's footprint; None
    when there is neither) with where it came from (``fence_source``), and the colour the images
    show (``params.colour`` resolved from both scenes' colour statistics) and the change rule
    (``params.change_rule`` resolved from the class histograms of the label sets it uses)."""

    pair_id: int
    site: SiteSpec
    t1: PairScene
    t2: PairScene
    cameras: tuple[tuple[str, Camera], ...]
    params: PairParams
    digest: str
    root: str
    recorded: bool
    fence: tuple[tuple[float, float], ...] | None = None
    fence_source: str = "none"
    colour: ColourPlan = ColourPlan("rgb")
    change_rule: ChangeRulePlan = ChangeRulePlan()

    @property
    def versions(self) -> PairVersions:
        return PairVersions(self.t1.label_set.version, self.t2.label_set.version)


def _pair_scene(session: Session, pair_id: int, scene_id: int, version: int | None) -> PairScene:
    scene = get_scene(session, scene_id)
    if scene.status != "tiled":
        raise PairError(
            f"pair {pair_id}: scene {scene_id} is not tiled: run `siteline scene tile {scene_id}` "
            "(or `siteline release build`, which tiles and processes what it needs)."
        )
    tiling = scene.statistics.tiling
    site_version = site_of(session, scene.site_id).version
    if tiling is not None and tiling.site_version != site_version:
        raise PairError(
            f"pair {pair_id}: scene {scene_id} was tiled under version {tiling.site_version} of its site, which "
            f"is at version {site_version} now (its taxonomy or fence changed): `siteline release build` tiles it "
            f"again, or `siteline scene tile {scene_id}`."
        )
    return PairScene(
        scene_id, tile_source(session, scene_id), label_set_ref(session, scene_id, version),
        tiling.generation if tiling is not None else 0,
    )  # fmt: skip


def _change_rule(
    session: Session, site: SiteSpec, ids: tuple[int, int], versions: Mapping[int, int], choice: str
) -> ChangeRulePlan:
    first, second = ((sid, label_set(session, sid, versions[sid]).class_histogram) for sid in ids)
    return resolve_change_rule(choice, first, second, site.taxonomy)


def pair_change_rule(
    session: Session, pair_id: int, choice: str, pinned: Mapping[int, int] | None = None
) -> ChangeRulePlan:
    """The change rule ``choice`` resolves to for ``pair_id`` on each scene's newest label set (or
    the version ``pinned`` names), with how the scenes' class schemes differ: what a release states
    before any pair is processed."""
    pair = get_pair(session, pair_id)
    ids = (pair.t1_scene_id, pair.t2_scene_id)
    newest = newest_versions(session, list(ids))
    chosen = {sid: (pinned or {}).get(sid, newest.get(sid, 1)) for sid in ids}
    return _change_rule(session, site_of(session, pair.site_id), ids, chosen, choice)


def plan_pair(
    session: Session, store: Store, pair_id: int, params: PairParams, pinned: Mapping[int, int] | None = None
) -> PairPlan:
    """The plan of processing ``pair_id`` with ``params`` on each scene's newest label set, or the
    version ``pinned`` (scene id -> version) names (one transaction). :class:`PairError` names what is
    missing (an unknown pair, an untiled scene); :class:`LabelSetError` a pinned version that does not
    exist."""
    pair = get_pair(session, pair_id)
    ids = (pair.t1_scene_id, pair.t2_scene_id)
    sites = {get_scene(session, sid).site_id for sid in ids}
    if sites != {pair.site_id}:
        raise PairError(
            f"pair {pair_id} joins scenes of different sites ({', '.join(map(str, sorted(sites)))})."
        )
    newest = newest_versions(session, list(ids))
    chosen = {sid: (pinned or {}).get(sid, newest.get(sid, 1)) for sid in ids}
    t1, t2 = (_pair_scene(session, pair_id, sid, chosen[sid]) for sid in ids)
    site = site_of(session, pair.site_id)
    rule = _change_rule(session, site, ids, chosen, params.change_rule)
    scans = [get_scene(session, sid).statistics.scan for sid in ids]
    s1, s2 = ((sid, sc.colour_stats if sc else None) for sid, sc in zip(ids, scans, strict=True))
    colour = resolve_colour(params.colour, s1, s2, shading=params.shading)
    digest = output_digest(
        params, (t1.label_set.version, t2.label_set.version), (t1.generation, t2.generation), rule.rule,
        colour.look,
    )  # fmt: skip
    fence, fence_source = site.fence, "site fence"
    if fence is None:
        scan = scans[1]
        outline = scan.footprint if scan is not None else None
        fence = tuple((float(x), float(y)) for x, y in outline) if outline else None
        fence_source = f"footprint of scene {ids[1]}" if fence else "none"
    return PairPlan(
        pair_id, site, t1, t2, tuple(scene_cameras(session, ids[1])), params, digest,
        layout.pair_outputs(store, pair_id, digest), bool(pair_view_ids(session, pair_id, digest)),
        fence, fence_source, colour, rule,
    )  # fmt: skip
