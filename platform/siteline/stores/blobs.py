"""The content-addressed blob store of mission files (``<store>/blobs/<sha[:2]>/<sha[2:]>``)."""

from __future__ import annotations

from pathlib import Path

from siteline.stores import layout
from siteline.stores.base import Store


def put_blob(store: Store, source: Path, sha256: str) -> bool:
    """Copy ``source`` into the store under its hash (whole or not at all); return whether it was new.
    An existing blob is left as it is."""
    dest = layout.blob(store, sha256)
    if store.exists(dest):
        return False
    store.put_file(source, dest)
    return True


def put_blob_bytes(store: Store, data: bytes, sha256: str) -> bool:
    """Store ``data`` under its hash; return whether it was new."""
    dest = layout.blob(store, sha256)
    if store.exists(dest):
        return False
    store.put_bytes(data, dest)
    return True


def remove_blobs(store: Store, shas: list[str]) -> None:
    for sha in shas:
        store.remove(layout.blob(store, sha))


def resolve_file(store: Store, storage: str, root_uri: str, rel: str, sha256: str) -> Path:
    """A local path holding a mission file's bytes: its blob (copied missions; fetched into the local
    cache from a remote store) or its original path (referenced missions)."""
    if storage == "copy":
        return store.local_file(layout.blob(store, sha256), sha256)
    return Path(root_uri) / rel
