"""Files written and read around the page cache (O_DIRECT), a shared primitive: the partition's run
files, written once by ingest and read once by the tile stage, and the copy of a mission's files
into the store, flushed to disk and not read back soon.

On virtual machines the first touch of a page the host has taken back costs about 2 ns a byte of
kernel time, and a file written through the page cache takes a new page for every 4 KiB it holds: a
40M-point partition cost each ingest worker 1.7 s of its 3.8 (docs/performance.md). Direct I/O moves
the bytes between the disk and a buffer each thread reuses, at the price of waiting for the disk.
Direct I/O wants whole aligned blocks; where a file system refuses it (tmpfs, say) these functions
fall back to the page cache, with the same results.
"""

from __future__ import annotations

import fcntl
import io
import mmap
import os
import shutil
import threading
from pathlib import Path

BLOCK = 4096  # alignment of direct I/O offsets, lengths and buffers: a multiple of any block size
COPY_BYTES = 8 << 20  # bytes a copy moves at a time
_DIRECT = getattr(os, "O_DIRECT", 0)
_LOCAL = threading.local()


def _buffer(size: int) -> memoryview:
    """This thread's page-aligned scratch buffer, at least ``size`` bytes (grown, then reused)."""
    buf: mmap.mmap | None = getattr(_LOCAL, "buf", None)
    if buf is None or len(buf) < size:
        buf = mmap.mmap(-1, -(-max(size, 1 << 20) // BLOCK) * BLOCK)
        _LOCAL.buf = buf
    return memoryview(buf)


def _open(path: str, flags: int) -> tuple[int, bool]:
    """``path`` opened with ``flags``, direct where the file system allows it: (fd, direct)."""
    if _DIRECT:
        try:
            return os.open(path, flags | _DIRECT, 0o666), True
        except OSError:  # EINVAL: no direct I/O here
            pass
    return os.open(path, flags, 0o666), False


def append_blocks(path: str, at: int, tail: bytes, data: memoryview) -> bytes:
    """Write ``tail + data`` at byte ``at`` of the file ``path`` (created if missing; ``at`` a multiple
    of :data:`BLOCK`), whole blocks only; return the bytes left over (less than a block), for the next
    call's ``tail`` or :func:`finish_blocks`."""
    size = len(tail) + data.nbytes
    whole = size // BLOCK * BLOCK
    buf = _buffer(size)
    try:
        buf[: len(tail)] = tail
        buf[len(tail) : size] = data.cast("B")
        fd, _ = _open(path, os.O_WRONLY | os.O_CREAT)
        try:
            _pwrite_all(fd, buf[:whole], at)
        finally:
            os.close(fd)
        return bytes(buf[whole:size])
    finally:
        buf.release()


def finish_blocks(path: str, at: int, tail: bytes) -> None:
    """Write the last bytes ``tail`` of the file ``path`` at byte ``at`` (through the page cache)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT, 0o666)
    try:
        _pwrite_all(fd, memoryview(tail), at)
    finally:
        os.close(fd)


def _pwrite_all(fd: int, data: memoryview, at: int) -> None:
    while data.nbytes:
        n = os.pwrite(fd, data, at)
        data, at = data[n:], at + n


def read_blocks(path: str, offset: int, views: list[memoryview]) -> int:
    """Fill ``views`` (writable bytes, in order) from byte ``offset`` of the local file ``path`` until
    they are full or the file ends, reading whole aligned blocks into this thread's buffer; return the
    bytes read."""
    want = sum(v.nbytes for v in views)
    lo = offset // BLOCK * BLOCK
    hi = -(-(offset + want) // BLOCK) * BLOCK
    buf = _buffer(hi - lo)
    try:
        fd, _ = _open(path, os.O_RDONLY)
        try:
            got = 0
            while got < hi - lo and (n := os.preadv(fd, [buf[got : hi - lo]], lo + got)):
                got += n
        finally:
            os.close(fd)
        at = offset - lo
        return spread(buf[at : at + max(0, min(got - at, want))], views)
    finally:
        buf.release()


def spread(data: memoryview | bytes, views: list[memoryview]) -> int:
    """Copy ``data`` into ``views`` (writable bytes) in order until either ends; the bytes copied."""
    data, done = memoryview(data), 0
    for v in views:
        if done == data.nbytes:
            break
        n = min(v.nbytes, data.nbytes - done)
        v[:n] = data[done : done + n]
        done += n
    return done


def copy_to_disk(source: Path, dest: Path) -> None:
    """Copy ``source`` to the new file ``dest`` and flush it to disk, around the page cache where the
    file system allows it (a 1.36 GB copy: 2.0 s of CPU through the cache here, 0.6 s direct);
    elsewhere a kernel copy (sendfile), then fsync."""
    fd, direct = _open(str(dest), os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    if not direct:
        os.close(fd)
        shutil.copyfile(source, dest)
        with open(dest, "rb") as fh:
            os.fsync(fh.fileno())
        return
    buf = _buffer(COPY_BYTES)
    view = buf[:COPY_BYTES]
    try:
        at = 0
        with open(source, "rb", buffering=0) as src:
            while n := _fill(src, view):
                if n % BLOCK:  # the tail, not a whole block: written through the cache
                    fcntl.fcntl(fd, fcntl.F_SETFL, fcntl.fcntl(fd, fcntl.F_GETFL) & ~_DIRECT)
                _pwrite_all(fd, view[:n], at)
                at += n
        os.fsync(fd)
    finally:
        os.close(fd)
        view.release()
        buf.release()


def _fill(src: io.RawIOBase, view: memoryview) -> int:
    """Read into ``view`` until it is full or the file ends; the bytes read."""
    n = 0
    while n < len(view) and (k := src.readinto(view[n:])):
        n += k
    return n
