"""Scene registration: camera poses (COLMAP + Sim3 georegistration, DJI XMP, or planned from the point
cloud), alignment checks."""

from siteline.register.scene import AlignmentPolicy, check_alignment, planned_cameras, register_cameras
from siteline.register.xmp import camera_from_photo, photo_center_crs

__all__ = ["AlignmentPolicy", "camera_from_photo", "check_alignment", "photo_center_crs", "planned_cameras",
           "register_cameras"]
