"""Mission ingest: inventory, photo metadata, point-cloud statistics (DESIGN.md §1, §9)."""

from siteline.ingest.photos import PhotoMeta, read_photo_meta

__all__ = ["PhotoMeta", "read_photo_meta"]
