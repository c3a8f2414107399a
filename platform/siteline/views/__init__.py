"""Synthetic views: ground plane, vertical / mirror / forward strategies, rejection, sampling (DESIGN.md §5).

Names are imported from their modules (``siteline.views.generate``, ``params``, ...); this package
front imports nothing, so the persisted parameters do not pull in the renderer and torch."""
