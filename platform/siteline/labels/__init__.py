"""3D change labels of a pair (DESIGN.md §4), both directions, tile by tile.

Names are imported from their modules; this front imports nothing, so the label parameters
(``siteline.records.params.labels``) do not pull in the tile store and zarr."""
