"""Compiled kernels: the per-point loops of ingest and tiling, plain ``numba.njit`` functions (pure
functions over arrays, no siteline imports beyond the record schema).

numpy runs a pipeline of whole-array passes, each a trip through memory; a kernel fuses them into one
loop over the points. Each is compiled on its first call and cached on disk beside its module, so a
worker process loads it instead of compiling again. Importing a kernel module imports numba (its cost is
in docs/ARCHITECTURE.md). ``NUMBA_DISABLE_JIT=1`` runs them as plain Python (slow; for a debugger).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar, cast

import numba

from siteline.pointpass import schema

F = TypeVar("F", bound=Callable[..., Any])


def kernel(fn: F) -> F:
    """``fn`` (nopython-compatible) as a numba kernel: compiled on its first call, cached on disk,
    releasing the GIL, numpy's error model (a division by zero gives inf, not an exception)."""
    return cast(F, numba.njit(cache=True, nogil=True, error_model="numpy")(fn))


# the schema's key packing compiled for the kernels: each key's layout is written once, in schema.py
cube_count_key = kernel(schema.cube_count_key)
group_key = kernel(schema.group_key)
order_key = kernel(schema.order_key)
pack_cube = kernel(schema.pack_cube)


def load() -> None:
    """Load one kernel from the disk cache: the start-up (about 1 s here) a process pays before its
    first kernel runs, which worker processes pay as they start (siteline.pointpass.workers)."""
    import numpy as np

    from siteline.pointpass.kernels import radix

    radix.run_starts(np.zeros(1, np.int64))
