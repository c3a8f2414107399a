"""The content-addressed blob store of mission files (``<store>/blobs/<sha[:2]>/<sha[2:]>``)."""

from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

from siteline.stores import layout
from siteline.stores.base import StagedFile, Store


class BlobStaging:
    """Files being copied into the blob store in a background thread, so the copy (and its flush to
    disk) runs beside the reading of the mission instead of after it: none appears in the store
    before :meth:`commit`, and :meth:`close` drops what was not committed. A blob already stored
    is not copied again."""

    def __init__(self, store: Store, files: list[tuple[Path, str]]) -> None:
        self.store = store
        self._thread = ThreadPoolExecutor(1, thread_name_prefix="siteline-blobs")
        self._staged: Future[list[tuple[str, StagedFile]]] = self._thread.submit(self._stage, files)

    def _stage(self, files: list[tuple[Path, str]]) -> list[tuple[str, StagedFile]]:
        staged: list[tuple[str, StagedFile]] = []
        try:
            for source, sha in files:
                dest = layout.blob(self.store, sha)
                if not self.store.exists(dest):
                    staged.append((sha, self.store.stage_file(source, dest)))
        except BaseException:
            for _, f in staged:
                f.discard()
            raise
        return staged

    def commit(self, added: list[str]) -> None:
        """Wait for the copies and make them appear in the store (:class:`StoreError` when one
        failed), appending to ``added`` the hash of each blob this call added (a blob another writer
        stored meanwhile is kept, and the copy dropped)."""
        pending = self._staged.result()  # what commit takes is popped: close drops the rest
        while pending:
            sha, staged = pending.pop(0)
            if self.store.exists(layout.blob(self.store, sha)):
                staged.discard()
            else:
                staged.commit()
                added.append(sha)

    def close(self) -> None:
        """Wait for the thread and drop every copy not committed."""
        self._thread.shutdown(wait=True)
        if self._staged.exception() is None:
            for _, staged in self._staged.result():
                staged.discard()


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
