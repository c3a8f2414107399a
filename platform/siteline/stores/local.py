"""The local store, and the one way siteline writes local files and folders whole: built under a
temporary name owned by this process (siteline.stores.owners), then renamed into place."""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from siteline.errors import StoreError
from siteline.stores.base import MARKER, StagedFile, Store, join
from siteline.stores.directio import copy_to_disk, read_blocks
from siteline.stores.owners import owner_tag, sweep_stale

if TYPE_CHECKING:
    import zarr


def local_path(uri: str) -> Path:
    """The path of a local address (a plain path or ``file://``)."""
    return Path(uri.split("://", 1)[1]) if "://" in uri else Path(uri)


def _temporary(dest: Path) -> Path:
    """A temporary name next to ``dest`` that this process owns (same suffix, so writers that choose
    a format by suffix still do); leftovers of writers that died are swept first."""
    dest.parent.mkdir(parents=True, exist_ok=True)
    sweep_stale(dest.parent, ".*.tmp-*")
    return dest.with_name(f".{dest.name}.tmp-{owner_tag()}{dest.suffix}")


def _prune(folder: Path) -> None:
    """Remove ``folder`` if it is empty (a failed or dropped copy leaves no empty folder behind)."""
    with contextlib.suppress(OSError):
        folder.rmdir()


def _flush(path: Path) -> None:
    with open(path, "rb") as fh:
        os.fsync(fh.fileno())


@contextmanager
def atomic_file(dest: Path) -> Iterator[Path]:
    """Yield a temporary path next to ``dest``; on a clean exit it is flushed to disk and renamed to
    ``dest``, so readers see the old file or the whole new one; on an error it is removed."""
    dest = Path(dest)
    tmp = _temporary(dest)
    try:
        yield tmp
        _flush(tmp)
        os.replace(tmp, dest)
    finally:
        tmp.unlink(missing_ok=True)


def write_file(dest: Path, write: Callable[..., object]) -> None:
    """Write the local file ``dest`` whole through ``write(fh)`` (:func:`atomic_file`)."""
    with atomic_file(dest) as tmp, open(tmp, "wb") as fh:
        write(fh)


def _remove_tree(path: Path) -> None:
    (path / MARKER).unlink(missing_ok=True)
    shutil.rmtree(path)


@contextmanager
def publish_folder(dest: Path, keep_existing: Callable[[Path], bool] | None = None) -> Iterator[Path]:
    """Build the local folder ``dest`` in the yielded path (which does not exist yet), next to ``dest``
    under a name this process owns; on a clean exit rename it into place, on an error remove it.
    A folder already at ``dest`` is replaced, unless ``keep_existing(dest)`` says to keep it (then the
    new one is dropped). Leftovers of writers that died are cleared; live writers' are not."""
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    sweep_stale(dest.parent, ".*.partial-*")
    container = dest.with_name(f".{dest.name}.partial-{owner_tag()}")
    container.mkdir()
    work = container / dest.name
    try:
        yield work
        if not work.is_dir():
            raise StoreError(f"nothing was built to publish at {dest}.")
        _move_into_place(work, dest, keep_existing)
    finally:
        shutil.rmtree(container, ignore_errors=True)


def _move_into_place(work: Path, dest: Path, keep_existing: Callable[[Path], bool] | None) -> None:
    if dest.exists() or dest.is_symlink():
        if keep_existing is not None and keep_existing(dest):
            return
        if dest.is_dir() and not dest.is_symlink():
            _remove_tree(dest)
        else:
            dest.unlink()
    try:
        os.replace(work, dest)
    except OSError:
        # another writer renamed its folder into place between our check and our rename
        if keep_existing is not None and dest.exists() and keep_existing(dest):
            return
        raise


def move(src: Path, dest: Path, *, replace: bool = False) -> None:
    """Move the local file or folder ``src`` to ``dest`` in one rename (so readers see it whole or not
    at all; both on one file system). An existing ``dest`` is replaced (a folder removed first) when
    ``replace``, else refused: :class:`StoreError` naming it, nothing moved."""
    src, dest = Path(src), Path(dest)
    if dest.exists() or dest.is_symlink():
        if not replace:
            raise StoreError(f"{dest} already exists: it is not replaced.")
        if dest.is_dir() and not dest.is_symlink():
            _remove_tree(dest)
        else:
            dest.unlink()
    os.replace(src, dest)


class LocalStore(Store):
    """A store in a local folder (or a file system mounted on every worker)."""

    def __init__(self, url: str, staging: Path) -> None:
        super().__init__(str(local_path(url)), staging)

    def ensure(self) -> None:
        Path(self.url).mkdir(parents=True, exist_ok=True)

    def exists(self, uri: str) -> bool:
        return local_path(uri).exists()

    def read_bytes(self, uri: str) -> bytes:
        try:
            return local_path(uri).read_bytes()
        except OSError as exc:
            raise StoreError(f"cannot read {uri} from the store: {exc}") from exc

    def read_into(self, uri: str, offset: int, buffers: list[memoryview]) -> int:
        """Read around the page cache in whole blocks (siteline.stores.directio: what it reads, a
        partition's runs, is read once)."""
        return read_blocks(str(local_path(uri)), offset, [b for b in buffers if b.nbytes])

    def put_bytes(self, data: bytes, uri: str) -> None:
        try:
            write_file(local_path(uri), lambda fh: fh.write(data))
        except OSError as exc:
            raise StoreError(f"cannot write {uri} into the store: {exc}") from exc

    def put_file(self, source: Path, uri: str) -> None:
        self.stage_file(source, uri).commit()

    def stage_file(self, source: Path, uri: str) -> StagedFile:
        """Copy ``source`` under a temporary name next to ``uri`` and flush it to disk now; ``commit()``
        renames it into place."""
        dest = local_path(uri)
        try:
            for attempt in (1, 2):
                tmp = _temporary(dest)
                try:
                    copy_to_disk(source, tmp)
                    break
                except FileNotFoundError:
                    # another writer's discard pruned the (then empty) folder between our mkdir and open
                    tmp.unlink(missing_ok=True)
                    if attempt == 2 or not source.exists():
                        raise
                except BaseException:
                    tmp.unlink(missing_ok=True)
                    _prune(dest.parent)
                    raise
        except OSError as exc:
            raise StoreError(f"cannot copy {source} into the store at {uri}: {exc}") from exc

        def commit() -> None:
            try:
                os.replace(tmp, dest)
            except OSError as exc:
                tmp.unlink(missing_ok=True)
                raise StoreError(f"cannot copy {source} into the store at {uri}: {exc}") from exc

        def discard() -> None:
            tmp.unlink(missing_ok=True)
            _prune(dest.parent)

        return StagedFile(commit=commit, discard=discard)

    def get_file(self, uri: str, dest: Path) -> None:
        try:
            shutil.copyfile(local_path(uri), dest)
        except OSError as exc:
            raise StoreError(f"cannot copy {uri} out of the store to {dest}: {exc}") from exc

    def remove(self, uri: str) -> None:
        p = local_path(uri)
        if p.is_dir() and not p.is_symlink():
            (p / MARKER).unlink(missing_ok=True)
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)
            if p.parent.parent.name == "blobs":  # a blob's shard folder (blobs/<sha[:2]>) left empty
                _prune(p.parent)

    def size(self, uri: str) -> int:
        path = local_path(uri)
        if path.is_file():
            return path.stat().st_size
        return sum(p.stat().st_size for p in path.rglob("*") if p.is_file()) if path.is_dir() else 0

    def names(self, uri: str) -> list[str]:
        p = local_path(uri)
        return sorted(c.name for c in p.iterdir()) if p.is_dir() else []

    def open_group(self, uri: str, mode: str = "r") -> zarr.Group:
        import zarr

        try:
            return zarr.open_group(str(local_path(uri)), mode=mode)  # type: ignore[arg-type]
        except FileNotFoundError as exc:
            raise StoreError(f"no Zarr group at {uri}: {exc}") from exc

    @contextmanager
    def publish(self, uri: str) -> Iterator[Path]:
        with publish_folder(local_path(uri), keep_existing=lambda d: self.is_complete(str(d))) as work:
            yield work
            if work.is_dir():
                (work / MARKER).write_bytes(b"")

    def local_file(self, uri: str, sha256: str | None = None) -> Path:
        return local_path(uri)


__all__ = ["LocalStore", "atomic_file", "join", "local_path", "publish_folder", "write_file"]
