"""3D change labels of a pair (DESIGN.md §4), both directions, tile by tile.

Names are imported on first use (PEP 562), so the label parameters (``siteline.labels.params``, read
by every command that takes release knobs) do not pull in the tile store and zarr.
"""

from __future__ import annotations

from siteline.lazy import lazy_names

_WHERE = {
    "CHANGED": "siteline.labels.change",
    "IGNORED": "siteline.labels.change",
    "UNCHANGED": "siteline.labels.change",
    "LabelResult": "siteline.labels.store",
    "auto_radius": "siteline.labels.store",
    "change_flags": "siteline.labels.change",
    "median_spacing": "siteline.labels.change",
    "write_labels": "siteline.labels.store",
}

__all__ = sorted(_WHERE)


__getattr__ = lazy_names(__name__, _WHERE)
