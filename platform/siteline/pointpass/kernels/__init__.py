"""Compiled kernels: the per-point loops of ingest and tiling, compiled with numba (a shared
primitive: pure functions over arrays, no siteline imports).

numpy runs a pipeline of whole-array passes, each a trip through memory; a kernel fuses them into one
loop over the points. Kernels are compiled on their first call (numba is imported then, so commands
that never tile start without it) and cached on disk beside their module, so a worker process loads
them instead of compiling again. ``NUMBA_DISABLE_JIT=1`` runs them as plain Python (slow; for a
debugger).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, MutableMapping
from typing import Any, TypeVar, cast

F = TypeVar("F", bound=Callable[..., Any])


class _Lazy:
    """A kernel not compiled yet: its first call compiles every kernel of its module."""

    def __init__(self, fn: Callable[..., Any]) -> None:
        self.fn = fn
        functools.update_wrapper(self, fn)

    def __call__(self, *args: Any) -> Any:
        return _bind(self.fn.__globals__)[self.fn.__name__](*args)


def _bind(namespace: MutableMapping[str, Any]) -> MutableMapping[str, Any]:
    """Replace every lazy kernel a module holds by its numba dispatcher, a kernel imported from
    another module by that module's (so kernels can call each other)."""
    import numba

    for name, value in list(namespace.items()):
        if not isinstance(value, _Lazy):
            continue
        home = value.fn.__globals__
        if home is namespace:
            namespace[name] = numba.njit(cache=True, nogil=True, error_model="numpy")(value.fn)
        else:
            namespace[name] = _bind(home)[value.fn.__name__]
    return namespace


def kernel(fn: F) -> F:
    """Mark ``fn`` (nopython-compatible) as a kernel, compiled on first use."""
    return cast(F, _Lazy(fn))


def load() -> None:
    """Import numba and load one kernel from the disk cache: the start-up (about 1 s here) a process
    pays before its first kernel runs, which worker processes pay as they start (siteline.pointpass.workers)."""
    import numpy as np

    from siteline.pointpass.kernels import radix

    radix.run_starts(np.zeros(1, np.int64))
