"""A release as records: its items, a built draft, and what the CLI and flows are told."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

from siteline.records.enums import SPLITS, ReleaseStatus, Split
from siteline.schema import JsonObject

# the release layout this siteline builds (siteline.release.layout)
FORMAT = 2


@dataclass(frozen=True)
class ReleaseItem:
    """One image pair of a release: its id, split, pair and view index, the view's strategy, coverage
    (the smaller of the two renders'), change ratio and valid fraction, its sizes in pixels (width,
    height) as rendered and as stored (padded), the share of its rendered pixels ignored for each
    cause (siteline.codes.IGNORE_CAUSES; empty for outputs made before causes were
    recorded) and the share whose point came from the gap fill, and the synthetic camera that saw it
    (``schema/camera.schema.json``: site-local frame, metres; its size is ``size_px``). Shares are of the
    rendered image: ``valid`` and the causes add up to 1; the padding is ``padded_px`` less ``size_px``.
    change_visible: the share of its changed pixels whose colour differs between A and B (None:
    nothing changed, or not measured; no key then)."""

    id: str
    split: Split
    pair: int
    view: int
    strategy: str
    coverage: float
    change_ratio: float
    valid: float
    size_px: tuple[int, int]
    padded_px: tuple[int, int]
    ignore: Mapping[str, float] = field(default_factory=dict)
    filled: float = 0.0
    camera: Mapping[str, Any] | None = None
    change_visible: float | None = None

    def to_dict(self) -> JsonObject:
        """The manifest's item (no ``camera`` key where none is known)."""
        doc = asdict(self) | {
            "size_px": list(self.size_px),
            "padded_px": list(self.padded_px),
            "ignore": dict(self.ignore),
            "camera": dict(self.camera) if self.camera is not None else None,
        }
        for key in ("camera", "change_visible"):
            if doc[key] is None:
                del doc[key]
        return doc

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> ReleaseItem:
        """An item of a manifest (:meth:`to_dict`); ``padded_px`` defaults to ``size_px`` (items stored
        unpadded). KeyError, TypeError or ValueError on an item that is not one."""
        split = doc["split"]
        if split not in SPLITS:
            raise ValueError(f"item {doc['id']!r}: split {split!r} is none of {', '.join(SPLITS)}")
        size = (int(doc["size_px"][0]), int(doc["size_px"][1]))
        padded = doc.get("padded_px") or size
        return cls(
            id=str(doc["id"]), split=split, pair=int(doc["pair"]), view=int(doc["view"]),
            strategy=str(doc.get("strategy", "")), coverage=float(doc["coverage"]),
            change_ratio=float(doc["change_ratio"]), valid=float(doc["valid"]), size_px=size,
            padded_px=(int(padded[0]), int(padded[1])), ignore={k: float(v) for k, v in (doc.get("ignore") or {}).items()},
            filled=float(doc.get("filled", 0.0)), camera=doc.get("camera"),
            change_visible=None if doc.get("change_visible") is None else float(doc["change_visible"]),
        )  # fmt: skip


@dataclass(frozen=True)
class Manifest:
    """A release's manifest.json as read back (``schema/release.schema.json``): its format, name and version,
    items, the pairs of each split, the files it lists (path -> sha256), statistics, lineage and split rule
    (still documents); ``format`` as written (2, or ``siteline-release/1``; None where a manifest has
    none)."""

    format: int | str | None
    name: str
    version: str
    created: str
    code_version: str
    items: tuple[ReleaseItem, ...]
    splits: Mapping[str, tuple[int, ...]]
    files: Mapping[str, str]
    stats: JsonObject
    lineage: JsonObject
    split_rule: JsonObject

    @classmethod
    def from_dict(cls, doc: JsonObject) -> Manifest:
        """The record of a manifest document. KeyError, TypeError or ValueError where it is not one."""
        return cls(
            format=doc.get("format"), name=str(doc["name"]), version=str(doc["version"]), created=str(doc["created"]),
            code_version=str(doc["code_version"]), items=tuple(ReleaseItem.from_dict(it) for it in doc["items"]),
            splits={s: tuple(int(p) for p in doc["splits"][s]) for s in SPLITS},
            files={str(f["path"]): str(f["sha256"]) for f in doc["files"]},
            stats=dict(doc.get("stats") or {}), lineage=dict(doc["lineage"]),
            split_rule=dict(doc.get("split_rule") or {}),
        )  # fmt: skip

    @property
    def title(self) -> str:
        """``<name> <version>``."""
        return f"{self.name} {self.version}"

    def items_of(self, split: str) -> list[ReleaseItem]:
        """The items of ``split``, by id (the order every consumer of a split reads them in)."""
        return sorted((it for it in self.items if it.split == split), key=lambda it: it.id)


@dataclass(frozen=True)
class DraftRelease:
    """A draft built on disk at ``root``: its items, manifest hash and statistics, the parameters the
    catalog records (``release.parameters``), and the key (digest) of the outputs each pair drew on."""

    name: str
    version: str
    root: str
    manifest_sha256: str
    items: tuple[ReleaseItem, ...]
    stats: JsonObject
    parameters: JsonObject
    digests: Mapping[int, str] = field(default_factory=dict)


@dataclass(frozen=True)
class ReleaseOptions:
    """What a release build is asked for beyond its site, name and parameters: the pairs (None: every
    processed pair of the site), the version (None: the next by semantic versioning), label-set
    versions pinned per scene (scene id -> version; None: each scene's newest), whether to publish
    the draft, and the torch device the renders run on."""

    pair_ids: Sequence[int] | None = None
    version: str | None = None
    label_sets: Mapping[int, int] | None = None
    publish: bool = False
    device: str = "cpu"


@dataclass(frozen=True)
class ReleaseInfo:
    """A release as commands report it: name, version, status, where it lives, item count, manifest
    hash and statistics; why this version (its bump reason), and whether the build found the latest
    version up to date (same inputs: nothing was built)."""

    name: str
    version: str
    status: ReleaseStatus
    root: str
    items: int
    manifest_sha256: str | None
    stats: JsonObject
    reason: str = ""
    up_to_date: bool = False

    def to_dict(self) -> JsonObject:
        return asdict(self)


@dataclass(frozen=True)
class CameraView:
    """What auto settings need of one real camera: its image size (pixels), focal length in x
    (pixels) and its height above the scene's ground (metres)."""

    scene_id: int
    width: int
    height: int
    fx: float
    height_above_ground_m: float


@dataclass(frozen=True)
class SiteSurvey:
    """The site's registered cameras and the density of its sparsest scene (points/m2, or None)."""

    cameras: tuple[CameraView, ...]
    min_density_pts_m2: float | None
