"""Reading a taxonomy map: the class codes of a corrected file mapped to site classes."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from siteline.errors import LabelSetError, SchemaError
from siteline.site.taxonomy import Taxonomy

# how a corrected file's class codes are read: a code -> class mapping, "las" (the site taxonomy's own
# LAS source codes, e.g. ASPRS), "site" (this site's class ids, for a file that lost its siteline
# record), or None (site ids, vouched for by the siteline record `scene export` writes)
TaxonomyMap = Mapping[int, str | int] | str | None
CODINGS = ("las", "site")


def coding_lut(taxonomy: Taxonomy, taxonomy_map: TaxonomyMap) -> tuple[np.ndarray, np.ndarray]:
    """(256,) uint8 class id per file code, and (256,) bool of the codes that are mapped."""
    if taxonomy_map == "las":
        return taxonomy.code_lut("las")
    if taxonomy_map is None or taxonomy_map == "site":
        return taxonomy.id_lut()
    if isinstance(taxonomy_map, str):
        raise LabelSetError(
            f"taxonomy map {taxonomy_map!r}: give a JSON file or one of {', '.join(CODINGS)}."
        )
    try:
        return taxonomy.id_lut(dict(taxonomy_map))
    except SchemaError as exc:
        raise LabelSetError(str(exc)) from exc


def parse_taxonomy_map(value: str) -> TaxonomyMap:
    """``--taxonomy-map``: one of :data:`CODINGS`, else the path of a JSON map."""
    return value if value in CODINGS else read_taxonomy_map(Path(value))


def read_taxonomy_map(path: Path) -> dict[int, str | int]:
    """A JSON object mapping the file's class codes to site classes (name or id):
    ``{"2": "ground", "6": "building", "64": 3}``."""
    try:
        doc = json.loads(Path(path).read_text())
    except FileNotFoundError as exc:
        raise LabelSetError(f"taxonomy map {path} does not exist.") from exc
    except ValueError as exc:
        raise LabelSetError(f"taxonomy map {path} is not JSON: {exc}") from exc
    if not isinstance(doc, dict) or not doc:
        raise LabelSetError(
            f'taxonomy map {path} must be a JSON object of code -> class, e.g. {{"2": "ground"}}.'
        )
    out: dict[int, str | int] = {}
    for code, target in doc.items():
        try:
            out[int(code)] = target
        except ValueError as exc:
            raise LabelSetError(f"taxonomy map {path}: key {code!r} is not a class code.") from exc
    return out
