"""Where siteline keeps its data: one store root, a local folder or any fsspec URL.

``SITELINE_STORE_URL`` names the root (default ``$SITELINE_HOME/stores``), e.g. ``s3://bucket/siteline``
for workers on several machines; the file system's endpoint and credentials come from fsspec's own
configuration (``FSSPEC_S3='{"endpoint_url": "http://minio:9000", "key": ..., "secret": ...}'`` or
the AWS variables), never from the catalog. Addresses recorded in the catalog are plain paths for a
local store and URLs otherwise.

Publishing a folder (a tile store, a label store, a pair's renders) is all-or-nothing. It is built
in a local staging folder, then renamed into place on a local store, or uploaded and then marked on
an object store, where nothing can be renamed. Either way a folder counts as present only when its
marker object :data:`MARKER` exists: it is written last and removed first.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from siteline.errors import StoreError
from siteline.hashing import sha256_file

MARKER = ".siteline-complete"
_LOCAL_PROTOCOLS = {"file", "local"}


def _fs(uri: str) -> tuple[Any, str]:
    import fsspec

    try:
        return fsspec.core.url_to_fs(uri)
    except (ImportError, ValueError) as exc:
        raise StoreError(
            f"cannot open the store {uri}: {exc}. Install the file system's package (s3fs for s3://, "
            "gcsfs for gs://) or fix the URL."
        ) from exc


def is_remote(uri: str) -> bool:
    """Whether ``uri`` is on another file system than the local one (an object store, say)."""
    if "://" not in uri:
        return False
    protocol = uri.split("://", 1)[0].lower()
    return protocol not in _LOCAL_PROTOCOLS


def local_path(uri: str) -> Path:
    """The path of a local address (a plain path or ``file://``)."""
    return Path(uri.split("://", 1)[1]) if "://" in uri else Path(uri)


def join(uri: str, *parts: str) -> str:
    """``uri`` with ``parts`` appended ('/'-separated for URLs and POSIX paths alike)."""
    return "/".join([uri.rstrip("/"), *(p.strip("/") for p in parts)])


def exists(uri: str) -> bool:
    """Whether a file (or, locally, a folder) exists at ``uri``."""
    if not is_remote(uri):
        return local_path(uri).exists()
    fs, path = _fs(uri)
    return bool(fs.exists(path))


def is_complete(uri: str) -> bool:
    """Whether the folder at ``uri`` was published whole (its marker exists)."""
    return exists(join(uri, MARKER))


def read_bytes(uri: str) -> bytes:
    try:
        if not is_remote(uri):
            return local_path(uri).read_bytes()
        fs, path = _fs(uri)
        return fs.cat_file(path)
    except OSError as exc:
        raise StoreError(f"cannot read {uri} from the store: {exc}") from exc


def atomic_local_write(dest: Path, write) -> None:  # noqa: ANN001
    """Write the local file ``dest`` through ``write(fh)`` into a unique temporary name next to it,
    fsync, rename: readers see the old file or the whole new one."""
    dest.parent.mkdir(parents=True, exist_ok=True)
    # unique temporary name: concurrent writers may store the same content at the same time
    tmp = dest.with_name(f".{dest.name}.tmp-{uuid.uuid4().hex}")
    try:
        with open(tmp, "wb") as out:
            write(out)
            out.flush()
            os.fsync(out.fileno())
        os.replace(tmp, dest)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def put_bytes(data: bytes, uri: str) -> None:
    """Store ``data`` at ``uri`` whole or not at all (a rename locally; one PUT on object stores)."""
    try:
        if not is_remote(uri):
            atomic_local_write(local_path(uri), lambda fh: fh.write(data))
            return
        fs, path = _fs(uri)
        fs.pipe_file(path, data)
    except OSError as exc:
        raise StoreError(f"cannot write {uri} into the store: {exc}") from exc


def put_file(source: Path, uri: str) -> None:
    """Copy the local file ``source`` to ``uri`` whole or not at all."""
    try:
        if not is_remote(uri):
            with open(source, "rb") as src:
                atomic_local_write(local_path(uri), lambda fh: shutil.copyfileobj(src, fh, 8 * 2**20))
            return
        fs, path = _fs(uri)
        fs.put_file(str(source), path)
    except OSError as exc:
        raise StoreError(f"cannot copy {source} into the store at {uri}: {exc}") from exc


def get_file(uri: str, dest: Path) -> None:
    """Copy the stored file ``uri`` to the local path ``dest``."""
    try:
        if not is_remote(uri):
            shutil.copyfile(local_path(uri), dest)
            return
        fs, path = _fs(uri)
        fs.get_file(path, str(dest))
    except OSError as exc:
        raise StoreError(f"cannot copy {uri} out of the store to {dest}: {exc}") from exc


def remove(uri: str) -> None:
    """Remove the file or folder at ``uri`` (its marker first); a missing one is fine."""
    if not is_remote(uri):
        p = local_path(uri)
        if p.is_dir():
            (p / MARKER).unlink(missing_ok=True)
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)
        return
    fs, path = _fs(uri)
    marker = join(path, MARKER)
    if fs.exists(marker):
        fs.rm_file(marker)
    if fs.exists(path):
        fs.rm(path, recursive=True)
    fs.invalidate_cache()


def open_group(uri: str, mode: str = "r"):  # noqa: ANN201
    """The Zarr group at ``uri`` (a local path or an fsspec URL)."""
    import zarr

    target = str(local_path(uri)) if not is_remote(uri) else uri
    try:
        return zarr.open_group(target, mode=mode)
    except FileNotFoundError as exc:
        raise StoreError(f"no Zarr group at {uri}: {exc}") from exc


class Store:
    """The store root and a local staging folder for what is published into it.

    ``url``: a local folder or an fsspec URL; ``staging``: a local folder for building folders before
    they are uploaded to a remote store and for caching files fetched from it.
    """

    def __init__(self, url: str, staging: Path) -> None:
        self.url = str(local_path(url)) if not is_remote(url) else url.rstrip("/")
        self.staging = Path(staging)

    def __repr__(self) -> str:
        return f"Store({self.url!r})"

    @property
    def remote(self) -> bool:
        return is_remote(self.url)

    def uri(self, *parts: str) -> str:
        """The address of ``parts`` under the root (what the catalog records)."""
        return join(self.url, *parts)

    def ensure(self) -> None:
        """Create the root (a local folder; on object stores the bucket must exist)."""
        if not self.remote:
            Path(self.url).mkdir(parents=True, exist_ok=True)
            return
        fs, path = _fs(self.url)
        bucket = path.split("/", 1)[0]
        try:
            if not fs.exists(bucket):
                raise StoreError(f"the store {self.url} needs its bucket {bucket!r}: create it first.")
        except PermissionError as exc:
            raise StoreError(f"cannot reach the store {self.url}: {exc}") from exc

    @contextmanager
    def publish(self, uri: str) -> Iterator[Path]:
        """Build a folder for ``uri`` in the yielded local path (which does not exist yet); on a clean
        exit it is published whole, on an error nothing is. A complete folder already at ``uri``
        (another worker's, with the same content) is kept and the new one dropped."""
        token = uuid.uuid4().hex[:12]
        name = uri.rstrip("/").rsplit("/", 1)[-1]
        if not self.remote:
            # next to the destination (one file system, so the rename is atomic), under a hidden name
            # that a later publish of the same folder clears if this one is killed
            dest = local_path(uri)
            dest.parent.mkdir(parents=True, exist_ok=True)
            for stale in dest.parent.glob(f".{dest.name}.partial-*"):
                shutil.rmtree(stale, ignore_errors=True)
            container = dest.with_name(f".{dest.name}.partial-{token}")
            container.mkdir()
        else:
            self.staging.mkdir(parents=True, exist_ok=True)
            container = Path(tempfile.mkdtemp(prefix=f"publish-{token}-", dir=self.staging))
        work = container / name
        try:
            yield work
            if not work.is_dir():
                raise StoreError(f"nothing was built to publish at {uri}.")
            (work / MARKER).write_bytes(b"")
            if not self.remote:
                if dest.exists():
                    if is_complete(uri):
                        return
                    shutil.rmtree(dest)
                os.replace(work, dest)
            else:
                self._upload(work, uri)
        finally:
            shutil.rmtree(container, ignore_errors=True)

    def _upload(self, work: Path, uri: str) -> None:
        fs, path = _fs(uri)
        if fs.exists(join(path, MARKER)):
            return
        if fs.exists(path):  # an earlier upload that never finished
            fs.rm(path, recursive=True)
        files = sorted(p for p in work.rglob("*") if p.is_file() and p.name != MARKER)
        try:
            fs.put([str(p) for p in files], [join(path, p.relative_to(work).as_posix()) for p in files])
            fs.pipe_file(join(path, MARKER), b"")
        except OSError as exc:
            raise StoreError(f"cannot upload {uri} to the store: {exc}") from exc
        finally:
            fs.invalidate_cache()

    def local_file(self, uri: str, sha256: str | None = None) -> Path:
        """A local path holding the bytes of ``uri``: itself on a local store, else a cached download
        (checked against ``sha256`` when given)."""
        if not is_remote(uri):
            return local_path(uri)
        name = sha256 or hashlib.sha256(uri.encode()).hexdigest()
        cached = self.staging / "cache" / name[:2] / name[2:]
        if cached.is_file():
            return cached
        cached.parent.mkdir(parents=True, exist_ok=True)
        tmp = cached.with_name(f".{cached.name}.tmp-{uuid.uuid4().hex}")
        try:
            get_file(uri, tmp)
            if sha256 is not None and sha256_file(tmp) != sha256:
                raise StoreError(f"{uri} does not match its checksum {sha256[:12]}: the store is damaged.")
            os.replace(tmp, cached)
        finally:
            tmp.unlink(missing_ok=True)
        return cached


# -- the content-addressed blob store of mission files (<store>/blobs, sha256 names) --------------


def blob_uri(store: Store, sha256: str) -> str:
    """Address of the content-addressed blob ``sha256`` under ``<store>/blobs``."""
    return store.uri("blobs", sha256[:2], sha256[2:])


def put_blob(store: Store, source: Path, sha256: str) -> bool:
    """Copy ``source`` into the store under its hash (whole or not at all); return whether it was new.
    An existing blob is left as it is."""
    dest = blob_uri(store, sha256)
    if exists(dest):
        return False
    put_file(source, dest)
    return True


def remove_blobs(store: Store, shas: list[str]) -> None:
    for sha in shas:
        remove(blob_uri(store, sha))


def resolve_file(store: Store, storage: str, root_uri: str, rel: str, sha256: str) -> Path:
    """A local path holding a mission file's bytes: its blob (copied missions; fetched into the local
    cache from a remote store) or its original path (referenced missions)."""
    if storage == "copy":
        return store.local_file(blob_uri(store, sha256), sha256)
    return Path(root_uri) / rel
