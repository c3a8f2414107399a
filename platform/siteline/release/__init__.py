"""Versioned, immutable dataset releases: build, publish, verify, diff, query (DESIGN.md §8).

Build: ``plan.plan_release`` (catalog) -> ``build.execute_build`` (write the draft) ->
``siteline.catalog.releases.record_draft``; publish: ``plan.plan_publish`` -> ``publish.move_into_place``
-> ``siteline.catalog.releases.record_published``; ``stage`` runs them.

Names are imported on first use (PEP 562), so ``siteline.release.query`` or the manifest reader do not
pull in the renderer and torch.
"""

from __future__ import annotations

from siteline.lazy import lazy_names

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
