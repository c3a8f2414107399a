"""Scene registration: camera poses (COLMAP + Sim3 georegistration, DJI XMP, or planned from the point
cloud), alignment checks.

Names are imported from their modules (this front imports nothing)."""
