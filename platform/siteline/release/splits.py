"""Splits of a release, disjoint by pair."""

from __future__ import annotations

import numpy as np


def split_pairs(
    pair_ids: list[int], seed: int, val_fraction: float = 0.15, test_fraction: float = 0.15
) -> dict[str, list[int]]:
    """Assign whole pairs to train/val/test (seeded): no view of one pair lands in two splits.

    One pair: all train. Two: train and test. Three or more: at least one each for val and test.
    """
    ids = sorted(pair_ids)
    order = [ids[i] for i in np.random.default_rng(seed).permutation(len(ids))]
    n = len(order)
    n_test = 0 if n < 2 else max(1, round(test_fraction * n))
    n_val = 0 if n < 3 else max(1, round(val_fraction * n))
    return {
        "test": sorted(order[:n_test]),
        "val": sorted(order[n_test : n_test + n_val]),
        "train": sorted(order[n_test + n_val :]),
    }
