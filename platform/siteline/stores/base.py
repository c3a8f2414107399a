"""The store interface: every read and write of siteline's data stores goes through a :class:`Store`.

A store has a root (a local folder or an fsspec URL) and a local staging folder. Addresses are full
paths (local) or URLs (elsewhere), as the catalog records them. Publishing a folder (a tile store, a
label store, a pair's renders) is all-or-nothing: the folder counts as present only when its marker
object :data:`MARKER` exists, written last and removed first.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import zarr

MARKER = ".siteline-complete"


def join(uri: str, *parts: str) -> str:
    """``uri`` with ``parts`` appended ('/'-separated for URLs and POSIX paths alike)."""
    return "/".join([uri.rstrip("/"), *(p.strip("/") for p in parts)])


@dataclass(frozen=True)
class StagedFile:
    """A file :meth:`Store.stage_file` has started to put: ``commit()`` makes it appear whole at its
    address, ``discard()`` drops it (either once)."""

    commit: Callable[[], None]
    discard: Callable[[], None]


# a manifest's address inside the data store, written relative to its root so a copied or restored
# home resolves it to its own store (siteline.stores.base.Store.resolve)
STORE_PREFIX = "store:"


def store_relative(address: str, root: str) -> str:
    """``address`` as ``store:<path under root>`` when it lies under the store ``root``, else as given."""
    root = root.rstrip("/")
    if address.startswith(root + "/"):
        return STORE_PREFIX + address[len(root) + 1 :]
    return address


class Store(ABC):
    """A store root (``url``) and a local ``staging`` folder (folders being built for a remote store,
    and a cache of files fetched from it). Methods take full addresses, so a store also reads
    addresses recorded under another root of the same kind."""

    def __init__(self, url: str, staging: Path) -> None:
        self.url = url
        self.staging = Path(staging)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.url!r})"

    def uri(self, *parts: str) -> str:
        """The address of ``parts`` under the root (what the catalog records)."""
        return join(self.url, *parts)

    def resolve(self, address: str) -> str:
        """A manifest's address under this store: ``store:<path>`` under its root; an absolute one
        (releases built before addresses were relative) as written."""
        if address.startswith(STORE_PREFIX):
            return join(self.url, address[len(STORE_PREFIX) :])
        return address

    @abstractmethod
    def ensure(self) -> None:
        """Create the root, or check that it can be reached; :class:`StoreError` says why not."""

    @abstractmethod
    def exists(self, uri: str) -> bool:
        """Whether a file (or a folder) exists at ``uri``."""

    def is_complete(self, uri: str) -> bool:
        """Whether the folder at ``uri`` was published whole (its marker exists)."""
        return self.exists(join(uri, MARKER))

    @abstractmethod
    def read_bytes(self, uri: str) -> bytes:
        """The bytes of the file at ``uri``; :class:`StoreError` naming it when it cannot be read."""

    @abstractmethod
    def read_into(self, uri: str, offset: int, buffers: list[memoryview]) -> int:
        """Fill ``buffers`` (writable bytes, in order) from byte ``offset`` of the file at ``uri`` until
        they are full or the file ends; return the bytes read (a ranged read)."""

    @abstractmethod
    def put_bytes(self, data: bytes, uri: str) -> None:
        """Store ``data`` at ``uri`` whole or not at all."""

    @abstractmethod
    def put_file(self, source: Path, uri: str) -> None:
        """Copy the local file ``source`` to ``uri`` whole or not at all."""

    def stage_file(self, source: Path, uri: str) -> StagedFile:
        """Put the local file ``source`` at ``uri`` in two steps: the slow part now (a caller may run
        it beside other work), the file's appearance at ``uri`` on ``commit()``. Here nothing is
        staged: ``commit()`` copies (a local store copies now and commits with a rename)."""
        return StagedFile(commit=lambda: self.put_file(source, uri), discard=lambda: None)

    @abstractmethod
    def get_file(self, uri: str, dest: Path) -> None:
        """Copy the stored file ``uri`` to the local path ``dest``."""

    @abstractmethod
    def remove(self, uri: str) -> None:
        """Remove the file or folder at ``uri`` (a folder's marker first); a missing one is fine."""

    @abstractmethod
    def size(self, uri: str) -> int:
        """Bytes held at ``uri``: a file's size, or a folder's files summed (0 when nothing is there)."""

    @abstractmethod
    def names(self, uri: str) -> list[str]:
        """The names of the files and folders directly in the folder ``uri``, sorted ([] when none)."""

    @abstractmethod
    def open_group(self, uri: str, mode: str = "r") -> zarr.Group:
        """The Zarr group at ``uri``; :class:`StoreError` when there is none."""

    @abstractmethod
    def publish(self, uri: str) -> AbstractContextManager[Path]:
        """Build a folder for ``uri`` in the yielded local path (which does not exist yet); on a clean
        exit it is published whole (marker last), on an error nothing is. A complete folder already
        at ``uri`` (another writer's, made from the same inputs) is kept and the new one dropped."""

    def publish_shared(self, uri: str) -> AbstractContextManager[str]:
        """As :meth:`publish`, but yields the address to build into where processes on other machines
        can write too (a cluster's workers): the local work folder on a local store; ``uri`` itself
        on a remote one (what is there is removed first; the marker is written last; on an error
        nothing is left)."""
        return _as_text(self.publish(uri))

    @abstractmethod
    def local_file(self, uri: str, sha256: str | None = None) -> Path:
        """A local path holding the bytes of ``uri``: the file itself on a local store, else a cached
        download (checked against ``sha256`` when given)."""


@contextmanager
def _as_text(folder: AbstractContextManager[Path]) -> Iterator[str]:
    with folder as work:
        yield str(work)


def walk_files(root: Path) -> Iterator[Path]:
    """Every file under the local folder ``root`` except the marker, sorted."""
    return iter(sorted(p for p in root.rglob("*") if p.is_file() and p.name != MARKER))
