"""Scene registration: camera poses (COLMAP + Sim3 georegistration, or DJI XMP), alignment checks."""

from siteline.register.xmp import camera_from_photo, photo_center_crs

__all__ = ["camera_from_photo", "photo_center_crs"]
