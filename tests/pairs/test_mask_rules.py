"""The recorded mask knobs: a pixel changed on one side and a hole on the other, and --all-points."""

from __future__ import annotations

import numpy as np
import pytest

from siteline.errors import LabelError, PairError
from siteline.labels.change import CHANGED, IGNORED, NOT_OBSERVED
from siteline.pairs.render import pair_mask
from siteline.records.params.pairs import PairParams

# pixels: both unchanged | A changed, B hole | A hole, B unchanged | A ignored class, B changed | both changed
HIT_A = np.array([True, True, False, True, True])
CH_A = np.array([0, CHANGED, 0, IGNORED, CHANGED], np.uint8)
HIT_B = np.array([True, False, True, True, True])
CH_B = np.array([0, 0, 0, CHANGED, CHANGED], np.uint8)


def test_one_side_hole_ignore_is_the_default() -> None:
    assert pair_mask(HIT_A, CH_A, HIT_B, CH_B).tolist() == [0, 255, 255, 255, 1]


def test_one_side_hole_changed_keeps_what_the_seeing_side_saw_change() -> None:
    m = pair_mask(HIT_A, CH_A, HIT_B, CH_B, "changed")
    assert m.tolist() == [0, 1, 255, 255, 1]  # a hole next to an unchanged or ignored point stays ignore
    assert np.array_equal(m, pair_mask(HIT_B, CH_B, HIT_A, CH_A, "changed"))  # still symmetric
    with pytest.raises(LabelError):
        pair_mask(HIT_A, CH_A, HIT_B, CH_B, "sometimes")


def test_a_place_the_other_scan_did_not_observe_is_ignore_unless_the_other_side_changed() -> None:
    # A not observed | A not observed, B changed | A not observed, B a hole | A changed, B not observed
    hit_a, hit_b = np.array([True, True, True, True]), np.array([True, True, False, True])
    ch_a = np.array([NOT_OBSERVED, NOT_OBSERVED, NOT_OBSERVED, CHANGED], np.uint8)
    ch_b = np.array([0, CHANGED, 0, NOT_OBSERVED], np.uint8)
    assert pair_mask(hit_a, ch_a, hit_b, ch_b).tolist() == [255, 1, 255, 1]
    assert pair_mask(hit_b, ch_b, hit_a, ch_a).tolist() == [255, 1, 255, 1]  # symmetric
    assert pair_mask(hit_a, ch_a, hit_b, ch_b, "changed").tolist() == [255, 1, 255, 1]


def test_mask_knobs_are_recorded_parameters() -> None:
    p = PairParams(one_side_hole="changed", all_points=True)
    assert p.to_dict()["one_side_hole"] == "changed" and p.to_dict()["all_points"] is True
    assert p.digest() != PairParams().digest()  # outputs of another rule are never reused
    with pytest.raises(PairError, match="one_side_hole"):
        PairParams(one_side_hole="maybe")
