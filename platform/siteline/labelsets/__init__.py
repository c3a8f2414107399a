"""Label-set versions of a scene's semantic classes: where they live, importing corrected labels as a
new version, and comparing versions (DESIGN.md §1: a correction is a new version, never an overwrite)."""

from siteline.labelsets.imports import DEFAULT_MAX_UNMATCHED, ImportResult, import_labels, read_taxonomy_map
from siteline.labelsets.store import labelset_uri, open_labelled_tiles

__all__ = [
    "DEFAULT_MAX_UNMATCHED",
    "ImportResult",
    "import_labels",
    "labelset_uri",
    "open_labelled_tiles",
    "read_taxonomy_map",
]
