"""Scene registration: camera poses (COLMAP + Sim3 georegistration, or DJI XMP), alignment checks."""

from siteline.register.scene import AlignmentPolicy, check_alignment, register_cameras
from siteline.register.xmp import camera_from_photo, photo_center_crs

__all__ = ["AlignmentPolicy", "camera_from_photo", "check_alignment", "photo_center_crs", "register_cameras"]
