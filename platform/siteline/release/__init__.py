"""Versioned, immutable dataset releases: build, publish, verify, diff, query (DESIGN.md §8).

Names are imported on first use (PEP 562), so ``siteline.release.query`` or the manifest reader do not
pull in the renderer and torch.
"""

from __future__ import annotations

import importlib
from typing import Any

_WHERE = {
    "ReleaseInfo": "siteline.release.build",
    "build_release": "siteline.release.build",
    "publish_release": "siteline.release.build",
    "release_root": "siteline.release.build",
    "read_manifest": "siteline.release.manifest",
    "verify_files": "siteline.release.manifest",
    "split_pairs": "siteline.release.splits",
}

__all__ = sorted(_WHERE)


def __getattr__(name: str) -> Any:
    if name not in _WHERE:
        raise AttributeError(f"module 'siteline.release' has no attribute {name!r}")
    return getattr(importlib.import_module(_WHERE[name]), name)
