"""3D change labels of a pair (DESIGN.md §4), both directions, tile by tile."""

from siteline.labels.change import CHANGED, IGNORED, UNCHANGED, change_flags, median_spacing
from siteline.labels.store import LabelResult, auto_radius, write_labels

__all__ = [
    "CHANGED",
    "IGNORED",
    "UNCHANGED",
    "LabelResult",
    "auto_radius",
    "change_flags",
    "median_spacing",
    "write_labels",
]
