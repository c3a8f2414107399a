"""Reading a taxonomy map: the class codes of a corrected file mapped to site classes."""

from __future__ import annotations

import json
from pathlib import Path

from siteline.errors import LabelSetError


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
