"""Level assignment: the fast path gives exactly what the plain definition gives."""

from __future__ import annotations

import numpy as np
import pytest

from siteline.pointpass import lod
from siteline.records.tiling import TileSpec


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
    last = spec.level_count - 1
    pts = counts.astype(np.int64)
    pts[:, 2] -= pts[:, 2].min()
    want = lod._assign_by_sorting(pts, order, lod._cell_counts(spec, last), last, np.full(n, 255, np.uint8))
    assert np.array_equal(got, want)
    assert (got <= last).all()
