"""Label-set versions of a scene's semantic classes: reading a scene with one, importing corrected
labels as a new version, and comparing versions (DESIGN.md §1: a correction is a new version, never
an overwrite).

Names are imported from their modules (this front imports nothing)."""
