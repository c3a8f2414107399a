"""The content-addressed file store under ``<store>/blobs`` (sha256 names)."""

from __future__ import annotations

from pathlib import Path

from siteline import stores
from siteline.stores import Store


def blob_uri(store: Store, sha256: str) -> str:
    return store.uri("blobs", sha256[:2], sha256[2:])


def put_blob(store: Store, source: Path, sha256: str) -> bool:
    """Copy ``source`` into the store under its hash (whole or not at all); return whether it was new.
    An existing blob is left as it is."""
    dest = blob_uri(store, sha256)
    if stores.exists(dest):
        return False
    stores.put_file(source, dest)
    return True


def remove_blobs(store: Store, shas: list[str]) -> None:
    for sha in shas:
        stores.remove(blob_uri(store, sha))


def resolve_file(store: Store, storage: str, root_uri: str, rel: str, sha256: str) -> Path:
    """A local path holding a mission file's bytes: its blob (copied missions; fetched into the local
    cache from a remote store) or its original path (referenced missions)."""
    if storage == "copy":
        return store.local_file(blob_uri(store, sha256), sha256)
    return Path(root_uri) / rel
