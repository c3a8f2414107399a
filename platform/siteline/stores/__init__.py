"""Where siteline keeps its data: one store root, a local folder or any fsspec URL, behind one
interface (:class:`Store`: :class:`LocalStore` or :class:`FsspecStore`).

``SITELINE_STORE_URL`` names the root (default ``$SITELINE_HOME/stores``), e.g. ``s3://bucket/siteline``
for workers on several machines. :func:`open_store` is the one place that tells a local address from a
remote one; :mod:`siteline.stores.layout` says where each thing lives; local files and folders outside
the store (releases, exports) are written whole with :func:`atomic_file` and :func:`publish_folder`,
and moved whole with :func:`move`.
"""

from __future__ import annotations

from pathlib import Path

from siteline.stores.base import MARKER, Store, join
from siteline.stores.local import LocalStore, atomic_file, local_path, move, publish_folder, write_file
from siteline.stores.remote import FsspecStore

_LOCAL_PROTOCOLS = {"file", "local"}


def is_remote(uri: str) -> bool:
    """Whether ``uri`` is on another file system than the local one (an object store, say)."""
    if "://" not in uri:
        return False
    return uri.split("://", 1)[0].lower() not in _LOCAL_PROTOCOLS


def open_store(url: str, staging: Path | None = None) -> Store:
    """The store rooted at ``url`` (a local folder or an fsspec URL); ``staging``: its local staging
    folder (default: one under the system's temporary folder, enough for reading)."""
    import tempfile

    stage = Path(staging) if staging is not None else Path(tempfile.gettempdir()) / "siteline-staging"
    return FsspecStore(url, stage) if is_remote(url) else LocalStore(url, stage)


__all__ = [
    "MARKER",
    "FsspecStore",
    "LocalStore",
    "Store",
    "atomic_file",
    "is_remote",
    "join",
    "local_path",
    "move",
    "open_store",
    "publish_folder",
    "write_file",
]
