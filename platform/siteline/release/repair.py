"""Finding and mending a release version left between two states by a killed build or publish, by
name: moved into place but not recorded as published, published with files still writable, a draft
on disk that is not the draft the catalog records, a draft with no folder."""

from __future__ import annotations

import hashlib
import logging
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from sqlalchemy.orm import Session

from siteline.catalog.context import StageContext
from siteline.catalog.releases import get_release, list_releases, record_published, remove_draft
from siteline.config import Settings
from siteline.records.runs import StageRun
from siteline.release.manifest import MANIFEST
from siteline.release.publish import make_read_only, writable
from siteline.stores import layout

log = logging.getLogger(__name__)
Kind = Literal["moved-not-recorded", "writable", "draft-differs", "draft-missing", "published-missing"]


@dataclass(frozen=True)
class Finding:
    """One thing wrong with a release version, and whether ``siteline release repair`` mends it."""

    name: str
    version: str
    kind: Kind
    message: str
    mendable: bool = True


def _sha(root: Path) -> str | None:
    path = root / MANIFEST
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else None


def inspect_release(session: Session, settings: Settings, name: str, version: str) -> list[Finding]:
    """What is wrong with release ``name`` ``version`` between the catalog and the disk."""
    rel = get_release(session, name, version)
    draft = layout.release_draft(settings.home, name, version)
    final = layout.release_published(settings.home, name, version)
    label = f"release {name} {version}"
    if rel.status == "published":
        if not final.is_dir():
            return [Finding(name, version, "published-missing", f"{label} is published but {final} is gone: "
                            "restore it from a backup.", False)]  # fmt: skip
        if writable(final):
            return [Finding(name, version, "writable", f"{label} is published but {len(writable(final))} of its "
                            "files and folders are still writable (a publish died before it finished).")]  # fmt: skip
        return []
    if not draft.exists() and final.is_dir() and _sha(final) == rel.manifest_sha256:
        return [Finding(name, version, "moved-not-recorded", f"{label} was moved into place at {final} but its "
                        "publish was never recorded (a publish died in between).")]  # fmt: skip
    if draft.is_dir() and _sha(draft) != rel.manifest_sha256:
        return [Finding(name, version, "draft-differs", f"the draft of {label} at {draft} is not the draft the "
                        "catalog records (a rebuild died before recording it): build it again.")]  # fmt: skip
    if not draft.exists() and not final.exists():
        return [
            Finding(name, version, "draft-missing", f"the draft of {label} has no folder: build it again.")
        ]
    return []


def repair_release(ctx: StageContext, name: str, version: str | None = None) -> list[str]:
    """Mend every version of ``name`` (or just ``version``) found wrong; return one line per change.
    A published folder that is gone cannot be mended here (it is reported, not changed)."""
    with ctx.catalog.lock(f"release:{name}"):
        with ctx.catalog.transaction() as s:
            versions = [version] if version else [r.version for r in list_releases(s, name)]
            found = [f for v in versions for f in inspect_release(s, ctx.settings, name, v)]
        return [line for f in found if (line := mend(ctx, f))]


def mend(ctx: StageContext, f: Finding) -> str:
    final = layout.release_published(ctx.settings.home, f.name, f.version)
    draft = layout.release_draft(ctx.settings.home, f.name, f.version)
    if f.kind == "moved-not-recorded":
        with ctx.catalog.transaction() as s:
            record_published(s, f.name, f.version, final, StageRun("publish_release", f"release:{f.name}:{f.version}",
                             {"repaired": True}, run_id=ctx.run_id))  # fmt: skip
        make_read_only(final)
        done = f"release {f.name} {f.version}: publish recorded and made read-only at {final}"
    elif f.kind == "writable":
        make_read_only(final)
        done = f"release {f.name} {f.version}: made read-only at {final}"
    elif f.kind in ("draft-differs", "draft-missing"):
        shutil.rmtree(draft, ignore_errors=True)
        with ctx.catalog.transaction() as s:
            remove_draft(s, f.name, f.version)
        done = f"release {f.name} {f.version}: the unrecorded draft removed; build it again"
    else:
        return ""
    log.info(done)
    return done
