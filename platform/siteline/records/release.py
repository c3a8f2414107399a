"""A release as records: its items, a built draft, and what the CLI and flows are told."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, NotRequired, TypedDict, cast

from siteline.records.enums import SPLITS, ReleaseStatus, Split
from siteline.schema import JSON, json_float, json_int, json_list, json_object, json_str

if TYPE_CHECKING:  # records.pairs reads this module's format through the pair parameters
    from siteline.records.pairs import ChangesDoc

# the release layout this siteline builds (siteline.release.layout)
FORMAT = 2


class ClassBalance(TypedDict):
    """Pixels of a split by class (padding counts as ignore) and its image count."""

    unchanged: int
    changed: int
    ignore: int
    images: int


class Coverage(TypedDict):
    """Mean and least share of a release's items where both renders hit."""

    mean: float
    min: float


class IgnoreTally(TypedDict):
    """Where the ignore pixels of some items come from (siteline.release.datasheet.ignore_breakdown):
    shares of all stored and of the rendered pixels, per cause, and the gap fill's share."""

    share: float
    share_of_rendered: float
    causes: dict[str, float]
    causes_of_rendered: dict[str, float]
    filled_of_rendered: float


class IgnoreBreakdown(IgnoreTally):
    """An :class:`IgnoreTally` of the whole release, with one per split."""

    per_split: dict[str, IgnoreTally]


class ReleaseStats(TypedDict, total=False):
    """A release's ``stats.json`` (and the manifest's ``stats``): class balance per split, coverage,
    mean change ratio per pair (pair id as text), image count, where the ignore pixels come from. Every
    key may be absent from a manifest of an earlier format."""

    class_balance: dict[str, ClassBalance]
    coverage: Coverage
    per_pair_change_ratio: dict[str, float]
    images: int
    ignore: IgnoreBreakdown


class SiteLineage(TypedDict):
    """The site in a release's lineage: name, CRS, origin and fence (site-local frame, metres), its
    version and taxonomy (absent from manifests of earlier versions)."""

    name: str
    crs: str
    origin: NotRequired[list[float]]
    fence_m: NotRequired[list[list[float]] | None]
    version: NotRequired[int]
    taxonomy: NotRequired[str]


class SceneLineage(TypedDict):
    """A scene in a release's lineage (siteline.release.plan.scene_lineage): its capture time, mission,
    label set, registration (a Registration's document) and tile checksum."""

    id: int
    capture_time: str
    mission_manifest_sha256: str
    label_set_version: NotRequired[int]
    label_set_source: NotRequired[str | None]
    label_set_sha256: NotRequired[str | None]
    registration: NotRequired[dict[str, JSON]]
    tile_checksum: NotRequired[str | None]
    las_software: NotRequired[str | None]


class ViewsLineage(TypedDict):
    """A pair's views in a release's lineage: how many were made of those asked, and how they were drawn
    (siteline.records.pairs.DrawnDoc: candidates, probed, rejected, changes; absent from earlier
    manifests)."""

    made: int
    asked: int | None
    candidates: NotRequired[int]
    probed: NotRequired[int]
    rejected: NotRequired[dict[str, int]]
    changes: NotRequired[ChangesDoc]


class PairLineage(TypedDict):
    """A pair in a release's lineage: its scenes, radius (metres), label sets, and the documents of its
    labels (ChangeLabels), colour (ColourPlan), change rule (ChangeRulePlan), ground (GroundUsed) and
    views (made, asked, and Drawn's figures)."""

    id: int
    t1: int
    t2: int
    radius_m: float
    label_sets: NotRequired[dict[str, int]]
    labels: dict[str, JSON]
    colour_source: NotRequired[str]
    colour: dict[str, JSON]
    fence: str
    change_rule: dict[str, JSON]
    ground: NotRequired[dict[str, JSON]]
    views: NotRequired[ViewsLineage]


class Lineage(TypedDict):
    """Where a release comes from: its site, scenes and pairs, its pair parameters (PairParams) and
    release parameters (ReleaseParams) as documents, preset, seeds and why this version."""

    sites: list[SiteLineage]
    scenes: list[SceneLineage]
    pairs: list[PairLineage]
    parameters: dict[str, JSON]
    preset: NotRequired[str | None]
    release_params: dict[str, JSON]
    seeds: NotRequired[dict[str, int]]
    version_reason: NotRequired[str]


class Padding(TypedDict):
    """The manifest's padding rule (siteline.release.layout)."""

    enabled: bool
    multiple_px: int
    min_side_px: int
    edges: str
    fill: dict[str, int]
    per_item: str


class Layout(TypedDict):
    """The manifest's folders (name -> what it holds) and padding rule."""

    folders: dict[str, str]
    padding: Padding


class FileEntry(TypedDict):
    """A file of a release: POSIX path under its root, size in bytes and sha256."""

    path: str
    size: int
    sha256: str


class SplitRule(TypedDict, total=False):
    """How a release's items were split (siteline.release.splits): the rule in words, its seed, and
    for spatial splits the shared footprint, the views left out, the bands' turn per pair and the
    changed share per split."""

    rule: str
    seed: int
    max_shared_footprint: float
    target_shared_footprint: float
    left_out: int
    left_out_items: list[list[int]]
    band_direction_deg: dict[str, float]
    changed_share: dict[str, float | None]


class LineageKey(TypedDict):
    """What decides whether a build is the latest version again (siteline.release.plan.next_version):
    its pairs, pair parameters (a PairParams document), format, padding and the label sets used
    (scene id as text -> version; known once the pairs are planned)."""

    pairs: list[int]
    params: dict[str, JSON]
    format: int
    pad: bool
    label_sets: NotRequired[dict[str, int]]


class ReleaseRecord(TypedDict, total=False):
    """What the catalog records of a release (``release.parameters``; siteline.release.build): its pair
    and release parameters (documents), preset, lineage key, pairs, label sets, each pair's output
    digest and smallest change resolved (metres), the radius ceiling, why this version, where its ignore
    pixels come from, the items left out of every split ([pair, view]) and how each pair's views cover
    its changed regions (siteline.records.pairs.ChangesDoc). Keys may be absent from a release built by
    an earlier version."""

    pair_params: dict[str, JSON]
    preset: str | None
    release_params: dict[str, JSON]
    lineage_key: LineageKey
    pairs: list[int]
    label_sets: dict[str, int]
    output_digests: dict[str, str]
    version_reason: str
    smallest_change_m: dict[str, float]
    radius_ceiling_m: float
    ignore: IgnoreBreakdown
    left_out: list[list[int]]
    changes_seen: dict[str, ChangesDoc]


class ManifestDoc(TypedDict):
    """A release's ``manifest.json`` (``schema/release.schema.json``): what this siteline writes, and
    what it reads back of a manifest of an earlier format (``format`` 1 or ``siteline-release/1``, or
    none; no layout, metric, statistics or split rule)."""

    format: NotRequired[int | str]
    layout: NotRequired[Layout]
    name: str
    version: str
    created: str
    code_version: str
    files: list[FileEntry]
    lineage: Lineage
    splits: dict[str, list[int]]
    split_rule: NotRequired[SplitRule]
    items: list[dict[str, JSON]]
    metric: NotRequired[dict[str, JSON]]
    stats: NotRequired[ReleaseStats]


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
    camera: Mapping[str, JSON] | None = None
    change_visible: float | None = None

    def to_dict(self) -> dict[str, JSON]:
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
    def from_dict(cls, doc: Mapping[str, JSON]) -> ReleaseItem:
        """An item of a manifest (:meth:`to_dict`); ``padded_px`` defaults to ``size_px`` (items stored
        unpadded). KeyError, TypeError or ValueError on an item that is not one."""
        split = doc["split"]
        if split not in SPLITS:
            raise ValueError(f"item {doc['id']!r}: split {split!r} is none of {', '.join(SPLITS)}")
        size_px = json_list(doc["size_px"], "size_px")
        size = (json_int(size_px[0]), json_int(size_px[1]))
        padded = json_list(doc.get("padded_px") or size, "padded_px")
        camera = doc.get("camera")
        visible = doc.get("change_visible")
        return cls(
            id=json_str(doc["id"], "id"), split=cast(Split, split), pair=json_int(doc["pair"], "pair"),
            view=json_int(doc["view"], "view"), strategy=json_str(doc.get("strategy", ""), "strategy"),
            coverage=json_float(doc["coverage"], "coverage"),
            change_ratio=json_float(doc["change_ratio"], "change_ratio"), valid=json_float(doc["valid"], "valid"),
            size_px=size, padded_px=(json_int(padded[0]), json_int(padded[1])),
            ignore={k: json_float(v, f"ignore.{k}") for k, v in json_object(doc.get("ignore") or {}, "ignore").items()},
            filled=json_float(doc.get("filled", 0.0), "filled"),
            camera=None if camera is None else json_object(camera, "camera"),
            change_visible=None if visible is None else json_float(visible, "change_visible"),
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
    stats: ReleaseStats
    lineage: Lineage
    split_rule: SplitRule

    @classmethod
    def from_dict(cls, doc: ManifestDoc) -> Manifest:
        """The record of a manifest document. KeyError, TypeError or ValueError where it is not one."""
        return cls(
            format=doc.get("format"), name=str(doc["name"]), version=str(doc["version"]), created=str(doc["created"]),
            code_version=str(doc["code_version"]), items=tuple(ReleaseItem.from_dict(it) for it in doc["items"]),
            splits={s: tuple(int(p) for p in doc["splits"][s]) for s in SPLITS},
            files={str(f["path"]): str(f["sha256"]) for f in doc["files"]},
            stats=doc.get("stats") or {}, lineage=doc["lineage"], split_rule=doc.get("split_rule") or {},
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
    stats: ReleaseStats
    parameters: ReleaseRecord
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
    stats: ReleaseStats
    reason: str = ""
    up_to_date: bool = False

    def to_dict(self) -> dict[str, JSON]:
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
