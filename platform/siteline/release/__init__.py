"""Versioned, immutable dataset releases: build, publish, verify, diff, query (DESIGN.md §8)."""

from siteline.release.build import ReleaseInfo, build_release, publish_release, release_root
from siteline.release.manifest import read_manifest, verify_files
from siteline.release.splits import split_pairs

__all__ = [
    "ReleaseInfo",
    "build_release",
    "publish_release",
    "read_manifest",
    "release_root",
    "split_pairs",
    "verify_files",
]
