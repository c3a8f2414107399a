"""A store on any fsspec file system (``s3://bucket/prefix``, ``gs://...``): what workers on several
machines share. Nothing can be renamed there, so a folder is built in the local staging folder,
uploaded, and then marked complete; its endpoint and credentials come from fsspec's configuration
(``FSSPEC_S3='{"endpoint_url": ..., "key": ..., "secret": ...}'`` or the AWS variables)."""

from __future__ import annotations

import hashlib
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from siteline.errors import StoreError
from siteline.hashing import sha256_file
from siteline.stores.base import MARKER, Store, join, walk_files
from siteline.stores.directio import spread
from siteline.stores.local import atomic_file
from siteline.stores.owners import owner_tag

if TYPE_CHECKING:
    import zarr


def file_system(uri: str) -> tuple[Any, str]:
    """(fsspec file system, path inside it) of ``uri``; :class:`StoreError` names a missing package."""
    import fsspec

    try:
        return fsspec.core.url_to_fs(uri)
    except (ImportError, ValueError) as exc:
        raise StoreError(
            f"cannot open the store {uri}: {exc}. Install the file system's package (s3fs for s3://, "
            "gcsfs for gs://) or fix the URL."
        ) from exc


def cached_download(store: Store, uri: str, sha256: str | None) -> Path:
    """``uri`` fetched once into ``store.staging/cache`` under its sha256 (or the hash of its address),
    checked against ``sha256`` when given; written whole (:func:`atomic_file`)."""
    name = sha256 or hashlib.sha256(uri.encode()).hexdigest()
    cached = store.staging / "cache" / name[:2] / name[2:]
    if cached.is_file():
        return cached
    with atomic_file(cached) as tmp:
        store.get_file(uri, tmp)
        if sha256 is not None and sha256_file(tmp) != sha256:
            raise StoreError(f"{uri} does not match its checksum {sha256[:12]}: the store is damaged.")
    return cached


class FsspecStore(Store):
    """A store at an fsspec URL."""

    def __init__(self, url: str, staging: Path) -> None:
        super().__init__(url.rstrip("/"), staging)

    def ensure(self) -> None:
        fs, path = file_system(self.url)
        bucket = path.split("/", 1)[0]
        try:
            if not fs.exists(bucket):
                raise StoreError(f"the store {self.url} needs its bucket {bucket!r}: create it first.")
        except PermissionError as exc:
            raise StoreError(f"cannot reach the store {self.url}: {exc}") from exc

    def exists(self, uri: str) -> bool:
        fs, path = file_system(uri)
        return bool(fs.exists(path))

    def read_bytes(self, uri: str) -> bytes:
        try:
            fs, path = file_system(uri)
            return bytes(fs.cat_file(path))
        except OSError as exc:
            raise StoreError(f"cannot read {uri} from the store: {exc}") from exc

    def read_into(self, uri: str, offset: int, buffers: list[memoryview]) -> int:
        """One ranged GET."""
        fs, path = file_system(uri)
        return spread(fs.cat_file(path, start=offset, end=offset + sum(b.nbytes for b in buffers)), buffers)

    def put_bytes(self, data: bytes, uri: str) -> None:
        try:
            fs, path = file_system(uri)
            fs.pipe_file(path, data)  # one PUT: whole or not at all
        except OSError as exc:
            raise StoreError(f"cannot write {uri} into the store: {exc}") from exc

    def put_file(self, source: Path, uri: str) -> None:
        try:
            fs, path = file_system(uri)
            fs.put_file(str(source), path)
        except OSError as exc:
            raise StoreError(f"cannot copy {source} into the store at {uri}: {exc}") from exc

    def get_file(self, uri: str, dest: Path) -> None:
        try:
            fs, path = file_system(uri)
            fs.get_file(path, str(dest))
        except OSError as exc:
            raise StoreError(f"cannot copy {uri} out of the store to {dest}: {exc}") from exc

    def remove(self, uri: str) -> None:
        fs, path = file_system(uri)
        marker = join(path, MARKER)
        if fs.exists(marker):
            fs.rm_file(marker)
        if fs.exists(path):
            fs.rm(path, recursive=True)
        fs.invalidate_cache()

    def size(self, uri: str) -> int:
        fs, path = file_system(uri)
        fs.invalidate_cache()
        return int(fs.du(path)) if fs.exists(path) else 0

    def names(self, uri: str) -> list[str]:
        fs, path = file_system(uri)
        fs.invalidate_cache()
        if not fs.isdir(path):
            return []
        return sorted(p.rstrip("/").rsplit("/", 1)[-1] for p in fs.ls(path, detail=False))

    def open_group(self, uri: str, mode: str = "r") -> zarr.Group:
        import zarr

        try:
            return zarr.open_group(uri, mode=mode)  # type: ignore[arg-type]
        except FileNotFoundError as exc:
            raise StoreError(f"no Zarr group at {uri}: {exc}") from exc

    @contextmanager
    def publish(self, uri: str) -> Iterator[Path]:
        self.staging.mkdir(parents=True, exist_ok=True)
        container = Path(tempfile.mkdtemp(prefix=f"publish-{owner_tag()}-", dir=self.staging))
        work = container / uri.rstrip("/").rsplit("/", 1)[-1]
        try:
            yield work
            if not work.is_dir():
                raise StoreError(f"nothing was built to publish at {uri}.")
            self._upload(work, uri)
        finally:
            shutil.rmtree(container, ignore_errors=True)

    def _upload(self, work: Path, uri: str) -> None:
        fs, path = file_system(uri)
        if fs.exists(join(path, MARKER)):
            return
        if fs.exists(path):  # an earlier upload that never finished
            fs.rm(path, recursive=True)
        files = list(walk_files(work))
        try:
            fs.put([str(p) for p in files], [join(path, p.relative_to(work).as_posix()) for p in files])
            fs.pipe_file(join(path, MARKER), b"")
        except OSError as exc:
            raise StoreError(f"cannot upload {uri} to the store: {exc}") from exc
        finally:
            fs.invalidate_cache()

    @contextmanager
    def publish_shared(self, uri: str) -> Iterator[str]:
        fs, path = file_system(uri)
        if fs.exists(join(path, MARKER)):
            raise StoreError(f"{uri} is already complete in the store; remove it first.")
        self.remove(uri)  # an earlier build that never finished
        try:
            yield uri
            fs.invalidate_cache()
            if not fs.exists(path):
                raise StoreError(f"nothing was built to publish at {uri}.")
            fs.pipe_file(join(path, MARKER), b"")
        except BaseException:
            self.remove(uri)
            raise
        finally:
            fs.invalidate_cache()

    def local_file(self, uri: str, sha256: str | None = None) -> Path:
        return cached_download(self, uri, sha256)
