"""Versioned, immutable dataset releases: build, publish, verify, diff, query (DESIGN.md §8).

Build: ``plan.plan_release`` (catalog) -> ``build.execute_build`` (write the draft) ->
``siteline.catalog.releases.record_draft``; publish: ``plan.plan_publish`` -> ``publish.move_into_place``
-> ``siteline.catalog.releases.record_published``; ``stage`` runs them.

Names are imported on first use (PEP 562), so ``siteline.release.query`` or the manifest reader do not
pull in the renderer and torch.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from siteline.lazy import lazy_names

if TYPE_CHECKING:  # mypy and editors see the real signatures; nothing is imported at run time
    from siteline.records.release import ReleaseInfo as ReleaseInfo
    from siteline.release.manifest import read_manifest as read_manifest
    from siteline.release.manifest import verify_files as verify_files
    from siteline.release.params import ReleaseParams as ReleaseParams
    from siteline.release.splits import split_pairs as split_pairs
    from siteline.release.stage import build_release as build_release
    from siteline.release.stage import publish_release as publish_release

_WHERE = {
    "ReleaseInfo": "siteline.records.release",
    "ReleaseParams": "siteline.release.params",
    "build_release": "siteline.release.stage",
    "publish_release": "siteline.release.stage",
    "read_manifest": "siteline.release.manifest",
    "verify_files": "siteline.release.manifest",
    "split_pairs": "siteline.release.splits",
}

__all__ = sorted(_WHERE)


__getattr__ = lazy_names(__name__, _WHERE)
