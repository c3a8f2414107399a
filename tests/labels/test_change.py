"""Change flags with the default taxonomy's geometry-only class."""

from __future__ import annotations

import numpy as np

from siteline.labels.change import change_flags


def test_unclassified_points_change_by_geometry_only() -> None:
    """ASPRS 0/1 'unclassified' (a geometry_only class): a counterpart of any kept class within the
    radius makes it unchanged, none makes it changed; other classes still compare classes."""
    from siteline.site.taxonomy import default_taxonomy

    tax = default_taxonomy()
    unc, ground, building = (tax.id_of(n) for n in ("unclassified", "ground", "building"))
    a = np.array([[0, 0, 0], [10, 0, 0], [20, 0, 0], [30, 0, 0]], np.float32)
    a_cls = np.array([unc, unc, ground, ground], np.uint8)
    b = np.array([[0, 0, 0.1], [20, 0, 0.1], [30, 0, 0.1]], np.float32)
    b_cls = np.array([building, unc, building], np.uint8)
    flags = change_flags(a, a_cls, b, b_cls, 0.5, tax.ignored_lut(), geometric=tax.geometry_only_lut())
    assert flags.tolist() == [0, 1, 0, 1]
    assert tax.by_name("unclassified").ignore is False
    assert tax.code_lut("las")[0][[0, 1]].tolist() == [unc, unc]
