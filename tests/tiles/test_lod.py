"""Level assignment and the packed sort behind it: the fast paths give exactly what the plain
definitions give."""

from __future__ import annotations

import numpy as np
import pytest

from siteline.records.tiling import TileSpec
from siteline.sorting import sort_by_key
from siteline.tiles import lod
from siteline.tiles.layout import level_count


@pytest.mark.parametrize("n", [1, 2, 17, 5_000, 60_000])
def test_nested_levels_equal_the_level_by_level_definition(n: int) -> None:
    """The head-of-finest-cube assignment (sorted once) keeps the same points per level as sorting
    every level's cube keys in the seeded order."""
    rng = np.random.default_rng(n)
    spec = TileSpec()
    # a dense patch and a sparse spread, z about a surface with a few outliers far above
    xy = np.r_[rng.uniform(0, 3_000, (n // 2, 2)), rng.uniform(0, 50_000, (n - n // 2, 2))]
    z = rng.normal(0, 200, n) + (rng.random(n) < 0.01) * 40_000
    counts = np.c_[xy, z].astype(np.int32)
    order = np.random.default_rng(3).permutation(n)
    got = lod.assign_levels(counts, spec, order)
    last = level_count(spec) - 1
    pts = counts.astype(np.int64)
    pts[:, 2] -= pts[:, 2].min()
    want = lod._assign_by_sorting(pts, order, lod._cell_counts(spec, last), last, np.full(n, 255, np.uint8))
    assert np.array_equal(got, want)
    assert (got <= last).all()


def test_packed_sort_equals_a_lexicographic_sort_and_falls_back_when_keys_are_wide() -> None:
    rng = np.random.default_rng(0)
    tie = rng.permutation(10_000)
    for high in (2**8, 2**40, 2**62):  # packed, packed, too wide to pack
        key = rng.integers(0, high, 10_000)
        k, t = sort_by_key(key, tie)
        order = np.lexsort((tie, key))
        assert np.array_equal(k, key[order]) and np.array_equal(t, tie[order])
