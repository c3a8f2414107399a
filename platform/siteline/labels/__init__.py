"""3D change labels of a pair (DESIGN.md §4), both directions, tile by tile.

Names are imported on first use (PEP 562), so the label parameters (``siteline.labels.params``, read
by every command that takes release knobs) do not pull in the tile store and zarr.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from siteline.lazy import lazy_names

if TYPE_CHECKING:  # mypy and editors see the real signatures; nothing is imported at run time
    from siteline.labels.change import CHANGED as CHANGED
    from siteline.labels.change import IGNORED as IGNORED
    from siteline.labels.change import UNCHANGED as UNCHANGED
    from siteline.labels.change import change_flags as change_flags
    from siteline.labels.change import median_spacing as median_spacing
    from siteline.labels.store import LabelResult as LabelResult
    from siteline.labels.store import auto_radius as auto_radius
    from siteline.labels.store import write_labels as write_labels

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
