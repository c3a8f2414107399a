"""Process a pair: 3D change both ways, synthetic views from the later scene, and every view rendered
on both scenes with its symmetric mask. Outputs live in the store, keyed by the parameters and the
label-set versions of both scenes, and are recorded in the catalog; a pair already processed with the
same parameters and label sets is reused, and a new label-set version never overwrites old outputs."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from datetime import UTC, datetime

import numpy as np

from siteline.catalog import Catalog
from siteline.catalog.labelsets import label_set, newest_versions
from siteline.catalog.models import Pair, Scene, Site
from siteline.catalog.pairs import pair_view_ids as catalog_pair_view_ids
from siteline.catalog.pairs import record_pair_outputs
from siteline.catalog.scenes import scene_cameras
from siteline.catalog.sites import site_spec
from siteline.catalog.stages import completed
from siteline.config import Settings
from siteline.errors import PairError
from siteline.labels.params import expected_false_change
from siteline.labels.store import attach_labels, auto_radius, write_labels
from siteline.labelsets import open_labelled_tiles
from siteline.pairs.params import PairParams
from siteline.pairs.render import render_pair_view
from siteline.pairs.sources import TilePointSource
from siteline.progress import Progress
from siteline.render.outputs import png_bytes
from siteline.stores import join
from siteline.tiles.scene import tiling_generation
from siteline.tolerances import RATIO_TOL, at_least
from siteline.views import NamedCamera, fit_ground_plane, generate_views
from siteline.views.generate import SyntheticView, key_sorted


@dataclass
class PairOutput:
    """A processed pair's outputs. label_sets: the label-set version of t1 and t2 they used; digest:
    the key of these outputs (parameters and label sets, :func:`output_digest`)."""

    pair_id: int
    t1: int
    t2: int
    radius_m: float
    root: str
    views: list[dict]
    labels: dict
    label_sets: dict[str, int] = field(default_factory=lambda: {"t1": 1, "t2": 1})
    digest: str = ""

    @property
    def view_count(self) -> int:
        return len(self.views)


def output_digest(params: PairParams, label_sets: tuple[int, int], tilings: tuple[int, int] = (0, 0)) -> str:
    """The key of a pair's outputs: the parameters' digest, extended by the label-set versions when
    either is not 1 and by the scenes' tiling generations when either was re-tiled (so outputs made
    before either was recorded keep their key, and a re-tiled scene never reuses outputs aligned
    with its old tile order)."""
    if label_sets == (1, 1) and tilings == (0, 0):
        return params.digest()
    text = f"{params.digest()}:labels:{label_sets[0]}:{label_sets[1]}"
    if tilings != (0, 0):
        text += f":tiles:{tilings[0]}:{tilings[1]}"
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def _output_root(settings: Settings, pair_id: int, digest: str) -> str:
    return settings.store.uri("pairs", f"pair-{pair_id}", digest)


def _pair_scenes(
    catalog: Catalog, pair_id: int, label_sets: dict[int, int] | None
) -> tuple[int, int, tuple[int, int], tuple[int, int]]:
    """(t1 id, t2 id, (t1 version, t2 version), (t1 tiling, t2 tiling)): the versions in
    ``label_sets`` (scene id -> version) or each scene's newest, and each scene's tiling generation
    (0 until it is re-tiled); LabelSetError when a pinned version does not exist."""
    with catalog.transaction() as s:
        pair = s.get(Pair, pair_id)
        if pair is None:
            raise PairError(f"no pair with id {pair_id}.")
        ids = (pair.t1_scene_id, pair.t2_scene_id)
        newest = newest_versions(s, list(ids))
        pinned = label_sets or {}
        versions = tuple(
            label_set(s, sid, pinned[sid]).version if sid in pinned else newest.get(sid, 1) for sid in ids
        )
        tilings = tuple(tiling_generation(s.get(Scene, sid)) for sid in ids)
    return ids[0], ids[1], versions, tilings


def pair_output(
    catalog: Catalog,
    settings: Settings,
    pair_id: int,
    params: PairParams,
    run_id: str | None = None,
    label_sets: dict[int, int] | None = None,
) -> PairOutput | None:
    """The stored outputs of ``pair_id`` processed with ``params`` and the label sets ``label_sets``
    (scene id -> version; each scene's newest by default), None when it was not. Outputs whose
    catalog rows are missing (a crash between the publish and the commit) get them now."""
    t1, t2, versions, tilings = _pair_scenes(catalog, pair_id, label_sets)
    digest = output_digest(params, versions, tilings)
    root = _output_root(settings, pair_id, digest)
    if not settings.store.is_complete(root):
        return None
    doc = json.loads(settings.store.read_bytes(join(root, "summary.json")))
    if not _view_ids(catalog, pair_id, digest):
        _record(
            catalog,
            pair_id,
            params,
            digest,
            doc["radius_m"],
            doc["labels"],
            doc["views"],
            root,
            datetime.now(UTC),
            run_id,
        )
    used = {"t1": versions[0], "t2": versions[1]}
    return PairOutput(pair_id, t1, t2, doc["radius_m"], root, doc["views"], doc["labels"], used, digest)


def process_pair(
    catalog: Catalog,
    settings: Settings,
    pair_id: int,
    params: PairParams | None = None,
    progress: Progress | None = None,
    device: str = "cpu",
    run_id: str | None = None,
    label_sets: dict[int, int] | None = None,
) -> PairOutput:
    """Labels, views and renders of ``pair_id`` with ``params`` and the classes of ``label_sets``
    (scene id -> label-set version; each scene's newest by default), reused when already made.

    Both scenes must be tiled (:class:`PairError` names the command otherwise); tiling them is the
    pipeline's job (``siteline.pipeline.process_pairs``), not this stage's."""
    params = params or PairParams()
    with catalog.transaction() as s:
        pair = s.get(Pair, pair_id)
        if pair is None:
            raise PairError(f"no pair with id {pair_id}.")
        t1, t2 = s.get(Scene, pair.t1_scene_id), s.get(Scene, pair.t2_scene_id)
        if t1.site_id != t2.site_id or pair.site_id != t1.site_id:
            raise PairError(f"pair {pair_id} joins scenes of different sites ({t1.site_id}, {t2.site_id}).")
        site = site_spec(s.get(Site, t1.site_id))
        ids = (t1.id, t2.id)
        untiled = [sc.id for sc in (t1, t2) if sc.status != "tiled"]
    if untiled:
        raise PairError(
            f"pair {pair_id}: scene {untiled[0]} is not tiled: run `siteline scene tile {untiled[0]}` "
            "(or `siteline release build`, which tiles and processes what it needs)."
        )
    _, _, versions, tilings = _pair_scenes(catalog, pair_id, label_sets)
    pinned = dict(zip(ids, versions, strict=True))
    digest = output_digest(params, versions, tilings)
    root = _output_root(settings, pair_id, digest)
    existing = pair_output(catalog, settings, pair_id, params, run_id, pinned)
    if existing is not None:
        return existing
    started = datetime.now(UTC)
    with catalog.transaction() as s:
        tiles1, _ = open_labelled_tiles(s, s.get(Scene, ids[0]), versions[0])
        tiles2, _ = open_labelled_tiles(s, s.get(Scene, ids[1]), versions[1])
        cams = scene_cameras(s, ids[1])
    ignored = site.taxonomy.ignored_lut()
    label_params = params.label_params()
    auto, radius_info = auto_radius(tiles1, tiles2, label_params.radius_multiplier)
    if label_params.radius_m is None:
        radius = auto
    else:
        radius = label_params.radius_m
        radius_info = radius_info | {
            "given": True,
            "multiplier": radius / (auto / label_params.radius_multiplier),
        }
    # what the chosen radius costs on unchanged surfaces, recorded with the labels (and the lineage)
    radius_info["expected_false_change"] = expected_false_change(radius_info["multiplier"])
    classes = "" if versions == (1, 1) else f"-ls{versions[0]}.{versions[1]}"
    label_uri = settings.store.uri("labels", f"pair-{pair_id}{classes}-r{int(round(radius * 1e6))}um.zarr")
    if settings.store.is_complete(label_uri):
        labels = dict(settings.store.open_group(label_uri).attrs) | {"uri": label_uri}
    else:
        if progress:
            progress("labels", 0, None)
        with settings.store.publish(label_uri) as work:
            labels = write_labels(tiles1, tiles2, radius, ignored, work).to_dict() | {"uri": label_uri}
    labels = labels | {"radius": radius_info}
    attach_labels(tiles1, label_uri, "t1")
    attach_labels(tiles2, label_uri, "t2")
    if not cams:
        raise PairError(
            f"pair {pair_id}: the later scene {ids[1]} has no cameras to derive views from "
            "(a LiDAR-only mission); ingest photos with it."
        )
    ground_id = site.taxonomy.id_of("ground")
    ground = tiles2.points(resolution=0.5, attributes=("class",))
    plane = fit_ground_plane(ground["xyz_m"][ground["class"] == ground_id], seed=params.seed)
    skip = np.array(
        [site.taxonomy.id_of(c) for c in ("snow", "noise") if c in {k.name for k in site.taxonomy.classes}],
        dtype=np.uint8,
    )
    source = TilePointSource(tiles2, skip, lod_factor=params.lod_factor, point_size_px=params.point_size_px)
    vp = params.view_params_spec()
    view_set = generate_views(
        [NamedCamera(n, c) for n, c in cams],
        plane,
        site.fence,
        source,
        vp,
        progress=(lambda k: progress("views", k, len(cams))) if progress else None,
    )
    if not view_set.views:
        raise PairError(
            f"pair {pair_id}: every synthetic view was rejected ({view_set.rejected}); lower "
            "--min-coverage or check the cameras."
        )
    records = []
    queue, reserve = list(view_set.views), list(view_set.reserve)
    rejected = dict(view_set.rejected)
    with settings.store.publish(root) as partial:
        for sub in ("A", "B", "label"):
            (partial / sub).mkdir(parents=True)
        kept: list[tuple[SyntheticView, dict]] = []
        while queue:
            v = queue.pop(0)
            r = render_pair_view(
                tiles1,
                tiles2,
                v.camera,
                params.scale,
                params.point_size_px,
                params.lod_factor,
                device,
                one_side_hole=params.one_side_hole,
                all_points=params.all_points,
            )
            low = not at_least(r.valid, params.min_valid, RATIO_TOL)
            if low:
                rejected["low_valid"] = rejected.get("low_valid", 0) + 1
                if reserve:
                    queue.append(reserve.pop(0))
            if progress:  # the total grows by each replacement
                progress("renders", 1, len(kept) + len(queue) + rejected.get("low_valid", 0) + (not low))
            if low:
                continue
            tmp = f"tmp-{len(kept):05d}.png"
            (partial / "A" / tmp).write_bytes(png_bytes(r.a))
            (partial / "B" / tmp).write_bytes(png_bytes(r.b))
            (partial / "label" / tmp).write_bytes(png_bytes(r.mask))
            kept.append(
                (
                    v,
                    {
                        "tmp": tmp,
                        "coverage_a": r.coverage_a,
                        "coverage_b": r.coverage_b,
                        "valid": r.valid,
                        "change_ratio": r.change_ratio,
                        "points_read": r.points_read,
                    },
                )
            )
        if not kept:
            raise PairError(
                f"pair {pair_id}: every rendered view had less than {params.min_valid:.0%} valid pixels "
                f"({rejected.get('low_valid', 0)} views); lower --min-valid or check the scenes' overlap."
            )
        # the kept views in key order, indexed 0..n-1 (an order that does not depend on the pool)
        by_view = {id(v): rec for v, rec in kept}
        for i, v in enumerate(key_sorted([v for v, _ in kept], params.seed)):
            v.index = i
            rec = by_view[id(v)]
            name = f"{i:04d}.png"
            tmp = rec.pop("tmp")
            for sub in ("A", "B", "label"):
                (partial / sub / tmp).rename(partial / sub / name)
            records.append(v.to_dict() | {"file": name} | rec)
        rejected = dict(sorted(rejected.items()))
        summary = {
            "pair": pair_id,
            "t1": ids[0],
            "t2": ids[1],
            "radius_m": radius,
            "params": params.to_dict(),
            "label_sets": {"t1": versions[0], "t2": versions[1]},
            "labels": labels,
            "ground_plane": plane.to_dict(),
            "candidates": view_set.candidates,
            "rejected": rejected,
            "views": records,
        }
        (partial / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    _record(catalog, pair_id, params, digest, radius, labels, records, root, started, run_id)
    used = {"t1": versions[0], "t2": versions[1]}
    return PairOutput(pair_id, ids[0], ids[1], radius, root, records, labels, used, digest)


def _record(
    catalog: Catalog,
    pair_id: int,
    params: PairParams,
    digest: str,
    radius: float,
    labels: dict,
    records: list[dict],
    root: str,
    started: datetime,
    run_id: str | None = None,
) -> None:
    with catalog.transaction() as s:
        record_pair_outputs(s, pair_id, digest, params.to_dict(), radius, labels, records, root)
        s.add(
            completed(
                "process_pair", f"pair:{pair_id}", params.to_dict() | {"radius_m": radius}, started, run_id
            )
        )


def _view_ids(catalog: Catalog, pair_id: int, digest: str) -> dict[int, int]:
    with catalog.transaction() as s:
        return catalog_pair_view_ids(s, pair_id, digest)
