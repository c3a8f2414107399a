"""Matching the points of a corrected labels file to a scene's stored points (pure functions).

A point's key is its position in int64 counts of the tile quantum (site frame, relative to its tile's
origin, exactly as the tile store holds it), its GPS time and its return number. Points with equal
keys are indistinguishable, so they are matched as multisets: the k-th file point of a key takes the
k-th stored point of that key. A file point whose key exists but whose stored copies are all taken is
a duplicate; one whose key does not exist matches nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

KEY_DTYPE = np.dtype([("x", "<i8"), ("y", "<i8"), ("z", "<i8"), ("gps_time", "<f8"), ("return_number", "u1")])
KEY_NAMES = ("x", "y", "z", "gps_time", "return_number")


def point_keys(counts: np.ndarray, gps_time: np.ndarray | None, return_number: np.ndarray) -> np.ndarray:
    """(N,) KEY_DTYPE keys of (N, 3) integer counts, (N,) GPS times (None: 0, for files without
    them) and (N,) return numbers."""
    keys = np.empty(len(counts), KEY_DTYPE)
    keys["x"], keys["y"], keys["z"] = (np.asarray(counts[:, k], dtype=np.int64) for k in range(3))
    keys["gps_time"] = 0.0 if gps_time is None else gps_time
    keys["return_number"] = return_number
    return keys


@dataclass
class Match:
    """stored / incoming: (M,) indices of matched pairs. duplicated / unmatched: (K,) bool over the
    incoming points that took no stored point (their key's stored copies were all taken / their key
    is not stored)."""

    stored: np.ndarray
    incoming: np.ndarray
    duplicated: np.ndarray
    unmatched: np.ndarray


def _group_ids(keys: np.ndarray) -> np.ndarray:
    """(N,) int64 ids, equal exactly where keys are equal."""
    order = np.lexsort([keys[name] for name in reversed(KEY_NAMES)])
    ks = keys[order]
    new = np.ones(len(ks), dtype=bool)
    if len(ks) > 1:
        same = np.ones(len(ks) - 1, dtype=bool)
        for name in KEY_NAMES:
            same &= ks[name][1:] == ks[name][:-1]
        new[1:] = ~same
    ids = np.empty(len(ks), dtype=np.int64)
    ids[order] = np.cumsum(new) - 1
    return ids


def _rank(ids: np.ndarray) -> np.ndarray:
    """(N,) rank of each element among the equal ids before it (0, 1, ...), in index order."""
    order = np.argsort(ids, kind="stable")
    s = ids[order]
    start = np.zeros(len(s), dtype=np.int64)
    if len(s):
        first = np.r_[True, s[1:] != s[:-1]]
        start = np.maximum.accumulate(np.where(first, np.arange(len(s)), 0))
    rank = np.empty(len(s), dtype=np.int64)
    rank[order] = np.arange(len(s)) - start
    return rank


def match_points(stored: np.ndarray, incoming: np.ndarray) -> Match:
    """Match ``incoming`` keys to ``stored`` keys (both KEY_DTYPE) as multisets."""
    ns = len(stored)
    ids = _group_ids(np.concatenate([stored, incoming]))
    ids_s, ids_i = ids[:ns], ids[ns:]
    rank_s, rank_i = _rank(ids_s), _rank(ids_i)
    width = int(max(rank_s.max(initial=0), rank_i.max(initial=0))) + 1
    _, si, ii = np.intersect1d(ids_s * width + rank_s, ids_i * width + rank_i, return_indices=True)
    taken = np.zeros(len(incoming), dtype=bool)
    taken[ii] = True
    known = np.isin(ids_i, ids_s)
    return Match(si.astype(np.int64), ii.astype(np.int64), ~taken & known, ~taken & ~known)
