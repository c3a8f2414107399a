"""Sorting one tile's points by an integer key (pure functions over arrays)."""

from __future__ import annotations

import numpy as np


def sort_by_key(key: np.ndarray, tie: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``key`` and ``tie`` (both (N,) non-negative integers, ``tie`` unique) sorted by (key, tie).

    Where both fit one 63-bit integer, one packed array is sorted by value: several times faster
    than an argsort (numpy sorts values with SIMD) and, the values being unique, the same order on
    every machine. Otherwise a lexicographic argsort."""
    bits = max(int(tie.max(initial=0)).bit_length(), 1)
    if int(key.max(initial=0)).bit_length() + bits <= 63:
        packed = np.sort(key.astype(np.int64) << bits | tie.astype(np.int64))
        return packed >> bits, packed & ((1 << bits) - 1)
    order = np.lexsort((tie, key))
    return key[order], tie[order]
