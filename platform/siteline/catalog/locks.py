"""Named locks that hold across processes and machines sharing the catalog: one writer at a time per
pair output, per release name, per scene's tiles or labels, per mission.

On PostgreSQL a lock is a session advisory lock held on a connection of its own; on SQLite (one
machine) an ``flock`` on a file beside the database, removed by its holder when done. Either way the lock is released when the block
ends or when its process dies (the server drops the session, the kernel the file lock), so a killed
writer never leaves a lock behind.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import logging
import os
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import sqlalchemy as sa

from siteline.errors import CatalogError

log = logging.getLogger(__name__)
POLL_S = 0.2
_memory_locks: dict[str, threading.Lock] = {}


def _key(name: str) -> int:
    """A signed 64-bit advisory-lock key of ``name``."""
    return int.from_bytes(hashlib.sha256(name.encode()).digest()[:8], "big", signed=True)


def lock_file(database: str, name: str) -> Path:
    """The file whose ``flock`` is lock ``name`` of the SQLite catalog at ``database``."""
    db = Path(database)
    return db.with_name(f"{db.name}.locks") / f"{hashlib.sha256(name.encode()).hexdigest()[:32]}.lock"


def _timed_out(name: str, timeout_s: float) -> CatalogError:
    return CatalogError(f"lock {name!r} is held by another writer and was not free within {timeout_s:g} s.")


@contextmanager
def _postgres(engine: sa.Engine, name: str, timeout_s: float | None) -> Iterator[None]:
    key = _key(name)
    deadline = None if timeout_s is None else time.monotonic() + timeout_s
    with engine.connect() as conn:
        while not conn.execute(sa.text("SELECT pg_try_advisory_lock(:k)"), {"k": key}).scalar_one():
            if deadline is not None and time.monotonic() > deadline:
                raise _timed_out(name, timeout_s or 0.0)
            time.sleep(POLL_S)
        conn.commit()
        try:
            yield
        finally:
            conn.execute(sa.text("SELECT pg_advisory_unlock(:k)"), {"k": key})
            conn.commit()


def _open_locked(path: Path, name: str, deadline: float | None, timeout_s: float | None) -> int:
    """A descriptor of ``path`` holding its ``flock``, the file still the one at ``path`` (a holder
    removes it when done: a waiter that got the lock on a removed file opens the new one)."""
    while True:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except FileExistsError:  # another holder pruned the folder while mkdir checked it: again
            if path.parent.exists() and not path.parent.is_dir():
                raise CatalogError(
                    f"{path.parent} should be the catalog's lock folder but is a file: move it away."
                ) from None
            continue
        try:
            fd = os.open(path, os.O_CREAT | os.O_RDWR, 0o644)
        except FileNotFoundError:  # the folder was pruned between the two calls
            continue
        try:
            while True:
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    break
                except BlockingIOError:
                    if deadline is not None and time.monotonic() > deadline:
                        raise _timed_out(name, timeout_s or 0.0) from None
                    time.sleep(POLL_S)
            try:
                same = os.stat(path).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
        except BaseException:
            os.close(fd)
            raise
        if same:
            return fd
        os.close(fd)


@contextmanager
def _file(path: Path, name: str, timeout_s: float | None) -> Iterator[None]:
    deadline = None if timeout_s is None else time.monotonic() + timeout_s
    fd = _open_locked(path, name, deadline, timeout_s)
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{name}\n{os.getpid()}\n".encode())
        try:
            yield
        finally:
            # removed while still held, so no lock file outlives its holder (a killed holder's file
            # stays until the next holder of that name is done)
            path.unlink(missing_ok=True)
            with contextlib.suppress(OSError):
                path.parent.rmdir()
            fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)


@contextmanager
def exclusive(engine: sa.Engine, name: str, timeout_s: float | None = None) -> Iterator[None]:
    """Hold lock ``name`` of the catalog behind ``engine`` for the block (waiting for it, at most
    ``timeout_s`` seconds when given: :class:`CatalogError` then). Locks are not re-entrant."""
    t0 = time.monotonic()
    url = engine.url
    if url.get_backend_name() == "postgresql":
        ctx = _postgres(engine, name, timeout_s)
    elif url.database and url.database != ":memory:":
        ctx = _file(lock_file(url.database, name), name, timeout_s)
    else:  # an in-memory catalog lives in one process
        ctx = _thread_lock(name, timeout_s)
    with ctx:
        waited = time.monotonic() - t0
        if waited > 1.0:
            log.info("lock %s acquired after waiting %.1f s", name, waited)
        yield


@contextmanager
def _thread_lock(name: str, timeout_s: float | None) -> Iterator[None]:
    lock = _memory_locks.setdefault(name, threading.Lock())
    if not lock.acquire(timeout=-1 if timeout_s is None else timeout_s):
        raise _timed_out(name, timeout_s or 0.0)
    try:
        yield
    finally:
        lock.release()
