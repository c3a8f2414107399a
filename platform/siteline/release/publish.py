"""Publishing a draft (the execute part; never touches the catalog): its checksums verified, the folder
renamed into place (atomic on one file system), then made read-only once the catalog says published."""

from __future__ import annotations

import logging
import os
import stat
from pathlib import Path

from siteline.errors import ImmutableError, ReleaseError
from siteline.release.manifest import verify_files
from siteline.release.plan import PublishPlan

log = logging.getLogger(__name__)


def move_into_place(plan: PublishPlan) -> None:
    """Verify the draft against its manifest and rename it to the published folder."""
    problems = verify_files(plan.draft)
    if problems:
        raise ReleaseError(
            f"draft {plan.name} {plan.version} does not match its manifest ({len(problems)} problems, e.g. "
            f"{problems[0]}): rebuild it."
        )
    if plan.final.exists():
        raise ImmutableError(f"{plan.final} already exists: a published version is never rewritten.")
    os.replace(plan.draft, plan.final)
    log.info("release %s %s moved into place at %s", plan.name, plan.version, plan.final)


def move_back(plan: PublishPlan) -> None:
    """Undo :func:`move_into_place` (the catalog did not record the publish)."""
    os.replace(plan.final, plan.draft)


def make_read_only(root: Path) -> None:
    """Remove every write permission under ``root`` (a published release is never rewritten)."""
    for p in root.rglob("*"):
        mode = p.stat().st_mode
        p.chmod(mode & ~(stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))
