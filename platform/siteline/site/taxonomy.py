"""The site class taxonomy (DESIGN.md §4): site classes stored as uint8 and the mapping from
source codes (ASPRS LAS classes, DJI Modify exports, hand corrections) to them."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import NotRequired, TypedDict

import numpy as np

from siteline.errors import SchemaError
from siteline.schema import SCHEMA_DIR, load_json, validated

DEFAULT_TAXONOMY_PATH = SCHEMA_DIR / "taxonomy.default.json"


def _rgb(values: list[int]) -> tuple[int, int, int]:
    r, g, b = (int(v) for v in values)
    return r, g, b


class ClassDoc(TypedDict):
    """A class of ``schema/taxonomy.schema.json``: id, name, whether it is ignored, colour (RGB 0-255)
    and whether it takes part in geometry only."""

    id: int
    name: str
    ignore: bool
    color: list[int]
    geometry_only: NotRequired[bool]


class TaxonomyDoc(TypedDict):
    """A taxonomy document (``schema/taxonomy.schema.json``)."""

    name: str
    classes: list[ClassDoc]
    source_codes: NotRequired[dict[str, dict[str, str]]]
    default_class: NotRequired[str]


@dataclass(frozen=True)
class SiteClass:
    """One site class: uint8 id, name, whether change detection ignores it, display colour (RGB), and
    whether its points are compared by geometry only (``geometry_only``: a point with a counterpart
    of any kept class within the radius is unchanged, one without is changed; ASPRS 0/1
    "unclassified", whose points may be anything)."""

    id: int
    name: str
    ignore: bool
    color: tuple[int, int, int]
    geometry_only: bool = False


@dataclass(frozen=True)
class Taxonomy:
    """Site classes and the source-code mappings into them.

    ``source_codes[source][code] = class name``; ``default_class`` receives unmapped codes.
    """

    name: str
    classes: tuple[SiteClass, ...]
    source_codes: dict[str, dict[int, str]] = field(default_factory=dict)
    default_class: str = "ignore"

    def __post_init__(self) -> None:
        ids = [c.id for c in self.classes]
        names = [c.name for c in self.classes]
        if len(set(ids)) != len(ids):
            raise SchemaError(f"taxonomy {self.name!r}: class ids repeat: {sorted(ids)}.")
        if len(set(names)) != len(names):
            raise SchemaError(f"taxonomy {self.name!r}: class names repeat: {sorted(names)}.")
        known = set(names)
        if self.default_class not in known:
            raise SchemaError(f"taxonomy {self.name!r}: default_class {self.default_class!r} is not a class.")
        if "ignore" not in known:
            raise SchemaError(
                f"taxonomy {self.name!r}: needs a class named 'ignore' (outside the fence goes there)."
            )
        for source, table in self.source_codes.items():
            for code, target in table.items():
                if target not in known:
                    raise SchemaError(
                        f"taxonomy {self.name!r}: source {source!r} code {code} maps to unknown class {target!r}."
                    )

    def by_name(self, name: str) -> SiteClass:
        for c in self.classes:
            if c.name == name:
                return c
        raise SchemaError(
            f"taxonomy {self.name!r} has no class {name!r}; classes: {[c.name for c in self.classes]}."
        )

    def id_of(self, name: str) -> int:
        return self.by_name(name).id

    def name_of(self, class_id: int) -> str:
        """The name of class ``class_id`` (``class <id>`` for an id the taxonomy lacks)."""
        return next((c.name for c in self.classes if c.id == class_id), f"class {class_id}")

    @property
    def ignore_id(self) -> int:
        return self.id_of("ignore")

    def ignored_ids(self) -> np.ndarray:
        """uint8 ids of the classes that change detection ignores."""
        return np.array([c.id for c in self.classes if c.ignore], dtype=np.uint8)

    def ignored_lut(self) -> np.ndarray:
        """(256,) bool: True at the ids of ignored classes and at ids not in the taxonomy."""
        lut = np.ones(256, dtype=bool)
        for c in self.classes:
            lut[c.id] = c.ignore
        return lut

    def ground_lut(self) -> np.ndarray:
        """(256,) bool: True at the id of the class named ``ground`` (none when the taxonomy has none)."""
        lut = np.zeros(256, dtype=bool)
        for c in self.classes:
            lut[c.id] = c.name == "ground"
        return lut

    def geometry_only_lut(self) -> np.ndarray:
        """(256,) bool: True at the ids of classes compared by geometry only."""
        lut = np.zeros(256, dtype=bool)
        for c in self.classes:
            lut[c.id] = c.geometry_only
        return lut

    def code_lut(self, source: str) -> tuple[np.ndarray, np.ndarray]:
        """(256,) uint8 lookup from source codes to class ids, and (256,) bool of codes that are mapped."""
        if source not in self.source_codes:
            raise SchemaError(
                f"taxonomy {self.name!r} has no mapping for source {source!r}; it maps {sorted(self.source_codes)}."
            )
        lut = np.full(256, self.id_of(self.default_class), dtype=np.uint8)
        known = np.zeros(256, dtype=bool)
        for code, target in self.source_codes[source].items():
            lut[code] = self.id_of(target)
            known[code] = True
        return lut, known

    def id_lut(self, mapping: dict[int, str | int] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Like :meth:`code_lut` for files whose codes are site class ids (a ``scene export``), or,
        with ``mapping``, codes mapped to a class (by name or id) of this taxonomy."""
        lut = np.full(256, self.ignore_id, dtype=np.uint8)
        known = np.zeros(256, dtype=bool)
        ids = {c.id for c in self.classes}
        if mapping is None:
            for i in ids:
                lut[i], known[i] = i, True
            return lut, known
        for code, target in mapping.items():
            if not 0 <= int(code) <= 255:
                raise SchemaError(f"taxonomy map: code {code} is not a LAS class code (0-255).")
            if isinstance(target, int) or (isinstance(target, str) and target.isdigit()):
                if int(target) not in ids:
                    raise SchemaError(
                        f"taxonomy map: code {code} maps to class id {target}, which taxonomy "
                        f"{self.name!r} does not have (ids {sorted(ids)})."
                    )
                lut[int(code)] = int(target)
            else:
                lut[int(code)] = self.id_of(str(target))
            known[int(code)] = True
        return lut, known

    def to_dict(self) -> TaxonomyDoc:
        classes: list[ClassDoc] = []
        for c in self.classes:
            doc: ClassDoc = {"id": c.id, "name": c.name, "ignore": c.ignore, "color": list(c.color)}
            if c.geometry_only:
                doc["geometry_only"] = True
            classes.append(doc)
        return {
            "name": self.name,
            "classes": classes,
            "source_codes": {
                source: {str(code): target for code, target in sorted(table.items())}
                for source, table in sorted(self.source_codes.items())
            },
            "default_class": self.default_class,
        }

    @classmethod
    def from_dict(cls, raw: object, source: str = "taxonomy") -> Taxonomy:
        """Validate ``raw`` against ``schema/taxonomy.schema.json`` and build the taxonomy."""
        doc = validated(raw, "taxonomy.schema.json", source, TaxonomyDoc)
        try:
            return cls(
                name=doc["name"],
                classes=tuple(
                    SiteClass(
                        int(c["id"]),
                        c["name"],
                        bool(c["ignore"]),
                        _rgb(c["color"]),
                        bool(c.get("geometry_only", False)),
                    )
                    for c in doc["classes"]
                ),
                source_codes={
                    src: {int(code): target for code, target in table.items()}
                    for src, table in doc.get("source_codes", {}).items()
                },
                default_class=doc.get("default_class", "ignore"),
            )
        except SchemaError as exc:
            raise SchemaError(f"{source}: {exc}") from exc


# LAS 1.4 R15 Table 17: the codes ASPRS defines (0-22; 23-63 reserved, 64-255 user-definable)
ASPRS_CODES = frozenset(range(23))


def detect_scheme(codes: dict[int, int], taxonomy: Taxonomy) -> str:
    """The classification scheme a LAS file's class codes (points per code) look like:
    ``unclassified`` (codes 0 and 1 only: nothing was classified), ``asprs`` (ASPRS standard codes,
    as DJI Terra and airborne vendors write them), ``asprs+site`` (with the codes the site taxonomy
    adds for construction, e.g. DJI Modify exports mapped in its ``las`` source), ``custom`` (codes
    neither defines), ``empty``."""
    present = {int(c) for c, n in codes.items() if n}
    site_codes = set(taxonomy.source_codes.get("las", {}))
    if not present:
        return "empty"
    if present <= {0, 1}:
        return "unclassified"
    if present <= ASPRS_CODES:
        return "asprs"
    if present <= ASPRS_CODES | site_codes:
        return "asprs+site"
    return "custom"


def load_taxonomy(path: Path) -> Taxonomy:
    """Read and validate a taxonomy JSON file."""
    return Taxonomy.from_dict(load_json(path, "taxonomy"), source=f"taxonomy file {path}")


def default_taxonomy() -> Taxonomy:
    """The taxonomy that ships in ``schema/taxonomy.default.json``."""
    return load_taxonomy(DEFAULT_TAXONOMY_PATH)
