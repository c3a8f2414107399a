"""Publishing a draft (the execute part; never touches the catalog): its checksums verified, the folder
renamed into place (atomic on one file system), then made read-only once the catalog says published."""

from __future__ import annotations

import logging
import stat
from pathlib import Path

from siteline.errors import ImmutableError, ReleaseError
from siteline.release.manifest import verify_files
from siteline.release.plan import PublishPlan
from siteline.stores import move

log = logging.getLogger(__name__)


def move_into_place(plan: PublishPlan) -> None:
    """Verify the draft against its manifest and the catalog's record of it, and rename it to the
    published folder."""
    problems = verify_files(plan.draft, plan.manifest_sha256)
    if problems:
        raise ReleaseError(
            f"draft {plan.name} {plan.version} does not match its manifest ({len(problems)} problems, e.g. "
            f"{problems[0]}): rebuild it."
        )
    if plan.final.exists():
        raise ImmutableError(f"{plan.final} already exists: a published version is never rewritten.")
    move(plan.draft, plan.final)
    log.info("release %s %s moved into place at %s", plan.name, plan.version, plan.final)


def move_back(plan: PublishPlan) -> None:
    """Undo :func:`move_into_place` (the catalog did not record the publish)."""
    move(plan.final, plan.draft)


WRITE = stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH


def make_read_only(root: Path) -> None:
    """Remove every write permission from ``root`` and everything under it (a published release is
    never rewritten); folders last, so a crash midway leaves them writable to finish the job."""
    entries = sorted(root.rglob("*"), key=lambda p: p.is_dir())
    for p in [*entries, root]:
        if not p.is_symlink():
            p.chmod(p.stat().st_mode & ~WRITE)


def writable(root: Path) -> list[Path]:
    """What under ``root`` (itself included) still has a write permission."""
    return [p for p in [root, *root.rglob("*")] if not p.is_symlink() and p.stat().st_mode & WRITE]
