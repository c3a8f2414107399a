"""Label-set versions of a scene's semantic classes: reading a scene with one, importing corrected
labels as a new version, and comparing versions (DESIGN.md §1: a correction is a new version, never
an overwrite)."""

from siteline.labelsets.execute import DEFAULT_MAX_UNMATCHED
from siteline.labelsets.mapping import read_taxonomy_map
from siteline.labelsets.stage import ImportOptions, import_labels
from siteline.labelsets.store import open_labelled

__all__ = ["DEFAULT_MAX_UNMATCHED", "ImportOptions", "import_labels", "open_labelled", "read_taxonomy_map"]
