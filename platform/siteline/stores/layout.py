"""Where everything lives, in one place: the store's folders (addresses under a store root, what the
catalog records) and the folders under ``SITELINE_HOME``.

Store root::

    blobs/<sha[:2]>/<sha[2:]>                          mission files and alignment samples by sha256
    tiles/scene-<id>.zarr, scene-<id>-g<n>.zarr        a scene's tile store (generation n > 0: re-tiled)
    labelsets/scene-<id>/v<version>.zarr               an imported label-set version's classes
    labels/pair-<id>[-ls<v1>.<v2>]-r<radius um>um.zarr a pair's 3D change labels
    pairs/pair-<id>/<output digest>/                   a pair's renders (A, B, label) and summary.json

``SITELINE_HOME``::

    catalog.sqlite, stores/ (the default store root), staging/ (folders built for a remote store and
    its download cache), tmp/ (spill files of running stages), releases/<name>/<version>/ (published),
    releases/<name>/.drafts/<version>/, previews/pairs/pair-<id>/<output digest>/ (A | B | mask
    images the flows show in the Prefect UI)
"""

from __future__ import annotations

import re
from pathlib import Path

from siteline.records.params.labels import LabelParams
from siteline.stores.base import Store, join

NEAREST = LabelParams(rule="nearest")


def blob(store: Store, sha256: str) -> str:
    return store.uri("blobs", sha256[:2], sha256[2:])


def tile_store(store: Store, scene_id: int, generation: int = 0) -> str:
    """``tiles/scene-<id>.zarr``; a re-tiling (generation g > 0) writes ``scene-<id>-g<g>.zarr`` beside
    it, so the old store stays whole until the new one is committed."""
    name = f"scene-{scene_id}.zarr" if generation == 0 else f"scene-{scene_id}-g{generation}.zarr"
    return store.uri("tiles", name)


def label_set(store: Store, scene_id: int, version: int) -> str:
    return store.uri("labelsets", f"scene-{scene_id}", f"v{version}.zarr")


def pair_labels(
    store: Store,
    pair_id: int,
    versions: tuple[int, int],
    radius_m: float,
    rule: str = "semantic",
    labels: LabelParams = NEAREST,
) -> str:
    """The 3D change labels of a pair at ``radius_m`` with the label-set ``versions`` of (t1, t2),
    by the change ``rule`` (siteline.labels.rule), the ``labels``' rule and the smallest region kept
    (siteline.records.params.labels; the nearest rule keeping every point names no suffix, as before both;
    the surface and adaptive rules are named with their versions, each with its probe
    when it has one, and ``-sparse2`` when a sparse surface's changed samples are kept whole)."""
    classes = "" if tuple(versions) == (1, 1) else f"-ls{versions[0]}.{versions[1]}"
    by = "" if rule == "semantic" else f"-{rule}"
    # the surface rule's second version ignores points the other scene never covered (stores of the
    # first, "-surface", are not reused); the adaptive rule's second ignores changed points beside the
    # other scene's ignored returns (siteline.labels.change.held_by_any; "-adaptive" not reused), its
    # third a point the other scan grazed (siteline.labels.change.SurfaceFit.grazed; "-adaptive2")
    by += {"nearest": "", "surface": "-surface2", "adaptive": "-adaptive3"}.get(
        labels.rule, f"-{labels.rule}"
    )
    by += "" if labels.min_region_points <= 1 else f"-m{labels.min_region_points}"
    by += "" if labels.rule == "nearest" or not labels.surface_probe else f"-p{labels.surface_probe:g}"
    # "-sparse2": the sparse test's cells below the site's origin no longer share keys across levels
    # (siteline.render.kernels._cell_key); stores of "-sparse" are not reused
    by += "-sparse2" if labels.sparse_regions and labels.min_region_points > 1 else ""
    return store.uri("labels", f"pair-{pair_id}{classes}-r{int(round(radius_m * 1e6))}um{by}.zarr")


def pair_label_stores(store: Store, pair_id: int) -> list[str]:
    """Every 3D change-label store of a pair, whatever its versions, radius and rule."""
    folder = store.uri("labels")
    return [join(folder, n) for n in store.names(folder) if re.fullmatch(rf"pair-{pair_id}[-.].*", n)]


def pair_folder(store: Store, pair_id: int) -> str:
    """The folder of every output of a pair (one per output digest)."""
    return store.uri("pairs", f"pair-{pair_id}")


def pair_outputs(store: Store, pair_id: int, digest: str) -> str:
    return store.uri("pairs", f"pair-{pair_id}", digest)


def default_store(home: Path) -> Path:
    return home / "stores"


def staging(home: Path) -> Path:
    return home / "staging"


def scratch(home: Path) -> Path:
    """Spill files of running stages (removed when they end; a killed stage's are swept later)."""
    return home / "tmp"


def partitions(home: Path) -> Path:
    """Partitions of point clouds into tile runs that ingest keeps for the tile stage
    (siteline.pointpass.partition; claimed by tiling, or swept after a week)."""
    return home / "partitions"


def releases(home: Path) -> Path:
    return home / "releases"


def release_draft(home: Path, name: str, version: str) -> Path:
    return releases(home) / name / ".drafts" / version


def release_published(home: Path, name: str, version: str) -> Path:
    return releases(home) / name / version


def previews(home: Path) -> Path:
    """Preview images for the UI (``siteline previews serve`` serves this folder and the releases)."""
    return home / "previews"


def pair_previews(home: Path, pair_id: int, digest: str) -> Path:
    return previews(home) / "pairs" / f"pair-{pair_id}" / digest
