"""The content-addressed file store under ``SITELINE_HOME/stores/blobs`` (sha256 names)."""

from __future__ import annotations

import os
import shutil
import uuid
from pathlib import Path

from siteline.errors import MissionError


def blob_path(store_dir: Path, sha256: str) -> Path:
    return Path(store_dir) / "blobs" / sha256[:2] / sha256[2:]


def put_blob(store_dir: Path, source: Path, sha256: str) -> bool:
    """Copy ``source`` into the store under its hash (temporary name, fsync, rename); return whether
    it was new. An existing blob is left as it is."""
    dest = blob_path(store_dir, sha256)
    if dest.exists():
        return False
    dest.parent.mkdir(parents=True, exist_ok=True)
    # unique temporary name: concurrent ingests may copy the same content at the same time
    tmp = dest.with_name(f".{dest.name}.tmp-{uuid.uuid4().hex}")
    try:
        with open(source, "rb") as src, open(tmp, "wb") as out:
            shutil.copyfileobj(src, out, 8 * 2**20)
            out.flush()
            os.fsync(out.fileno())
        os.replace(tmp, dest)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise MissionError(f"cannot copy {source} into the store {store_dir}: {exc}") from exc
    return True


def remove_blobs(store_dir: Path, shas: list[str]) -> None:
    for sha in shas:
        blob_path(store_dir, sha).unlink(missing_ok=True)


def resolve_file(store_dir: Path, storage: str, root_uri: str, rel: str, sha256: str) -> Path:
    """Where a mission file's bytes are: its blob (copied missions) or its original path (referenced)."""
    if storage == "copy":
        return blob_path(store_dir, sha256)
    return Path(root_uri) / rel
