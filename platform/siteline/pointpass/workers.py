"""Worker processes for the passes over a whole point cloud (ingest's scan and partition, tile
writing): one spawned pool per worker count, started on first use and kept for the life of the
process, so ingest and tiling in one process pay the start-up (about half a second a worker) once.

spawn, not fork: zarr, lazrs and a Prefect worker run threads that a forked child must not inherit.
A worker loads the compiled kernels as it starts (siteline.pointpass.kernels), and :func:`start_pool` starts
the workers ahead of the pass, so that this start-up runs beside other work (ingest's hashing).
Each worker keeps freed memory for reuse (glibc ``mallopt``, and one malloc arena for all its
threads, :data:`_WORKER_ENV`): the passes allocate arrays of hundreds of MB in turn, and on virtual
machines where the first touch of a page is slow, returning them to the system and faulting them in
again doubled the time of levelling a tile."""

from __future__ import annotations

import atexit
import ctypes
import ctypes.util
import os
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Executor, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from multiprocessing import get_context
from typing import Any

from siteline.errors import WorkerError

_M_TRIM_THRESHOLD = -1
_M_MMAP_MAX = -4
_POOLS: dict[int, ProcessPoolExecutor] = {}
# read by a worker's allocator as it starts (glibc fixes its number of arenas at the first thread's
# allocation, before an initializer could call mallopt): every thread on the one heap that keeps
# freed memory. A thread's own arena gives its freed top back, and zarr's event-loop thread, where a
# tile's shards are put in node order and compressed, faulted its pages in again for every shard: a
# tenth of the tile stage's time (docs/performance.md)
_WORKER_ENV = {"MALLOC_ARENA_MAX": "1"}
_LOCK = threading.Lock()


def keep_freed_memory() -> None:
    """Make this process's allocator reuse freed memory instead of returning it (glibc; elsewhere
    nothing). For worker processes only: their peak memory stays theirs until they exit."""
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name) if name else None
        mallopt = getattr(libc, "mallopt", None)
    except OSError:
        mallopt = None
    if mallopt is not None:
        mallopt(_M_MMAP_MAX, 0)  # large arrays from the heap, which keeps them for reuse
        mallopt(_M_TRIM_THRESHOLD, 2**30)


# how often (seconds) a worker checks that the process that started it is alive
PARENT_CHECK_S = 1.0


def exit_with_parent(parent: int, period_s: float = PARENT_CHECK_S) -> threading.Thread:
    """Start a daemon thread that ends this process once its parent ``parent`` is gone (it is then
    re-parented, so ``os.getppid()`` changes): a worker of a killed ingest does not live on holding its
    memory (a parent-death signal would fire when the parent's spawning thread ends, not the process,
    and the pool is shared by every thread)."""

    def watch() -> None:
        while True:
            if os.getppid() != parent:
                os._exit(1)
            time.sleep(period_s)

    thread = threading.Thread(target=watch, name="siteline-parent-watch", daemon=True)
    thread.start()
    return thread


def _start_worker(parent: int) -> None:
    """A worker's start-up: watch ``parent`` (the pid that spawned it, taken before the spawn: one
    read here would be init's if the parent died while this worker was still importing), keep freed
    memory, load the kernels."""
    import gc

    exit_with_parent(parent)
    from siteline.pointpass.kernels import load

    keep_freed_memory()
    load()
    gc.freeze()  # what start-up imported is never garbage: full collections no longer walk it


def _ready() -> None:
    """A task that returns once its worker has started."""


def start_pool(workers: int) -> None:
    """Start the workers of :func:`process_pool` ``(workers)`` now, without waiting for them."""
    process_pool(workers)


@contextmanager
def _worker_env() -> Iterator[None]:
    """:data:`_WORKER_ENV` in this process's environment while it spawns workers (a variable the
    user set keeps its value)."""
    added = {k: v for k, v in _WORKER_ENV.items() if k not in os.environ}
    os.environ.update(added)
    try:
        yield
    finally:
        for k in added:
            os.environ.pop(k, None)


def process_pool(workers: int) -> ProcessPoolExecutor:
    """The process's pool of ``workers`` spawned processes (started now if it is not running: each
    submit spawns a worker while none is idle, so the first ``workers`` spawn them all)."""
    with _LOCK:
        pool = _POOLS.get(workers)
        if pool is None:
            pool = ProcessPoolExecutor(
                max_workers=workers,
                mp_context=get_context("spawn"),
                initializer=_start_worker,
                initargs=(os.getpid(),),
            )
            with _worker_env():
                for _ in range(workers):
                    pool.submit(_ready)
            _POOLS[workers] = pool
        return pool


def discard_pool(workers: int) -> None:
    """Shut down the pool of ``workers`` (after a worker died, say); the next call starts a new one."""
    with _LOCK:
        pool = _POOLS.pop(workers, None)
    if pool is not None:
        pool.shutdown(wait=False, cancel_futures=True)


def pool_map(pool: Executor | None, fn: Callable[..., Any], *iterables: Iterable[Any]) -> Iterator[Any]:
    """``fn`` over ``iterables`` in ``pool`` (results in order), or in this process when None. A pool
    whose worker died is discarded so the next pass starts a fresh one, and the death is a
    :class:`WorkerError` (one line for the user, not a traceback)."""
    if pool is None:
        yield from map(fn, *iterables)
        return
    try:
        yield from pool.map(fn, *iterables)
    except BrokenProcessPool as exc:
        for workers, known in list(_POOLS.items()):
            if known is pool:
                discard_pool(workers)
        raise WorkerError(
            "a worker process died (killed, or out of memory) while reading or writing points; nothing "
            "was stored: run the command again (with fewer --workers if memory ran short)."
        ) from exc


@atexit.register
def shutdown_pools(wait: bool = False) -> None:
    """Shut down every pool of the process (``wait``: until its workers have exited)."""
    with _LOCK:
        pools = list(_POOLS.values())
        _POOLS.clear()
    for pool in pools:
        pool.shutdown(wait=wait, cancel_futures=True)
