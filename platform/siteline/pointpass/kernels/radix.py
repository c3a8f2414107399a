"""Sorting integer keys: a stable radix sort (the order of (key, index) in O(N) a digit) and the
runs of equal keys a sort leaves."""

from __future__ import annotations

import numpy as np

from siteline.pointpass.kernels import kernel

_DIGIT_BITS = 16


@kernel
def radix_order(key: np.ndarray) -> np.ndarray:
    """(N,) int64 positions that sort (N,) int64 ``key`` stably: the order of (key, index), by least
    significant 16-bit digits of ``key - key.min()``, one counting pass per digit its span needs."""
    n = key.shape[0]
    order = np.arange(n)
    if n == 0:
        return order
    lo, hi = key.min(), key.max()
    span = np.uint64(hi - lo)
    radix = 1 << _DIGIT_BITS
    mask = np.uint64(radix - 1)
    tmp = np.empty(n, np.int64)
    shift = np.uint64(0)
    while shift == 0 or (span >> shift) > 0:
        count = np.zeros(radix + 1, np.int64)
        for k in range(n):
            count[((np.uint64(key[order[k]] - lo) >> shift) & mask) + 1] += 1
        for d in range(radix):
            count[d + 1] += count[d]
        for k in range(n):
            p = order[k]
            digit = (np.uint64(key[p] - lo) >> shift) & mask
            tmp[count[digit]] = p
            count[digit] += 1
        order, tmp = tmp, order
        shift += np.uint64(_DIGIT_BITS)
        if shift >= 64:
            break
    return order


@kernel
def run_starts(key: np.ndarray) -> np.ndarray:
    """(M,) int64 index of the first of each run of equal values of (N,) ``key`` (sorted, or any
    order that keeps equal values together)."""
    n = key.shape[0]
    count = 0
    for k in range(n):
        if k == 0 or key[k] != key[k - 1]:
            count += 1
    starts = np.empty(count, np.int64)
    count = 0
    for k in range(n):
        if k == 0 or key[k] != key[k - 1]:
            starts[count] = k
            count += 1
    return starts


@kernel
def inverse(order: np.ndarray) -> np.ndarray:
    """(N,) int64 position of each element in the permutation ``order`` (N,): ``out[order[k]] = k``."""
    out = np.empty(order.shape[0], np.int64)
    for k in range(order.shape[0]):
        out[order[k]] = k
    return out
