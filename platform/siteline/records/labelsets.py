"""An imported label-set version as a record."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field

from siteline.schema import JSON


@dataclass(frozen=True)
class ExportedLabels:
    """What a LAS file's classes mean, as siteline writes it into the file's labels VLR on export
    (siteline.pointpass.labels_vlr): the site and scene, the label-set version, how the codes read
    (``site class ids``) and the site's taxonomy then (its JSON form). Read back from a file that may
    have been edited elsewhere, a value of the wrong type reads as None (and the import refuses it by name)."""

    site: str | None
    scene: int | None
    label_set_version: int | None
    classification: str = "site class ids"
    taxonomy: dict[str, JSON] = field(default_factory=dict)

    def to_dict(self) -> dict[str, JSON]:
        return asdict(self)

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON]) -> ExportedLabels:
        """From a file's VLR, which an editor may have mangled: a field of the wrong type reads as None
        (the taxonomy as empty), for the importer to refuse naming what is missing."""

        def count(key: str) -> int | None:
            value = doc.get(key)
            return value if isinstance(value, int) and not isinstance(value, bool) else None

        site, taxonomy = doc.get("site"), doc.get("taxonomy")
        return cls(
            site if isinstance(site, str) else None, count("scene"), count("label_set_version"),
            str(doc.get("classification", "")), dict(taxonomy) if isinstance(taxonomy, Mapping) else {},
        )  # fmt: skip


@dataclass(frozen=True)
class LabelSetImport:
    """A label-set version imported from a corrected file: where it is, and how the file's points
    matched the scene's. untouched: stored points the file does not hold (they keep the previous
    version's class). changes: changed points per "old -> new" class. key: what matched a point
    (position, GPS time, return number). created: False when no point changed class (no version is
    made; ``version`` is then the current one). merged_from: the earlier label set the file was
    exported from, when its changes from it were merged onto a newer parent (None: exported from the
    parent, or unknown)."""

    scene_id: int
    version: int
    parent_version: int
    uri: str
    file: str
    source_sha256: str
    points_in_file: int
    matched: int
    unmatched: int
    duplicated: int
    untouched: int
    changed: int
    changes: dict[str, int] = field(default_factory=dict)
    class_histogram: dict[str, int] = field(default_factory=dict)
    key: str = ""
    seconds: float = 0.0
    created: bool = True
    note: str | None = None
    max_unmatched: float = 0.001
    merged_from: int | None = None

    def to_dict(self) -> dict[str, JSON]:
        return asdict(self)

    def details(self) -> dict[str, JSON]:
        """What the catalog keeps of the match (``label_set.details``)."""
        keep = ("file", "points_in_file", "matched", "unmatched", "duplicated", "untouched", "changes", "key",
                "merged_from")  # fmt: skip
        return {k: getattr(self, k) for k in keep} | {"max_unmatched": self.max_unmatched}


@dataclass(frozen=True)
class LabelSetRef:
    """One label-set version of a scene as a reader needs it: version 1 is the tile store's own
    ``class`` (``uri`` None), later versions are stores of ``tiles/<tile>/class``; source and its
    sha256 say where the classes came from."""

    scene_id: int
    version: int
    uri: str | None
    source: str
    source_sha256: str | None = None
