"""Change codes, the one definition (DESIGN.md §4): per point (3D labels) and per pixel (2D masks,
``label_ignore/`` in releases, ``siteline.metrics``)."""

UNCHANGED = 0
CHANGED = 1
IGNORE = 255
