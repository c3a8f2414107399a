"""Views judged on what they teach: a rendered view with too few valid pixels is replaced by the next
view of the stratified order; the knob is part of the outputs' key and recorded."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from siteline.catalog.context import StageContext
from siteline.pairs.stage import process_pair
from siteline.records.params.pairs import PairParams

BASE = {"scale": 0.25, "point_size_px": 3, "views": 4, "seed": 0, "min_coverage": 0.3}


@pytest.mark.slow  # over 25 s on a 2-core machine: `make test-all` runs it
def test_low_valid_views_are_replaced(scenes, monkeypatch) -> None:
    from dataclasses import replace

    from siteline.views import generate

    settings, cat = scenes
    loose = process_pair(StageContext(cat, settings), 1, PairParams(**BASE, min_valid=0.0))
    valid = sorted(v.valid for v in loose.views)
    threshold = (valid[0] + valid[1]) / 2  # the least valid view falls under it
    # the probes judge min_valid before any render; with them passing every view, the rendered check
    # is what replaces a view (a probe's valid share is an upper bound, so renders can still fall short)
    judged = generate.probe
    monkeypatch.setattr(
        generate, "probe", lambda view, source, params: judged(view, source, replace(params, min_valid=0.0))
    )
    strict = process_pair(StageContext(cat, settings), 1, PairParams(**BASE, min_valid=threshold))
    monkeypatch.undo()
    assert strict.root != loose.root
    assert all(v.valid >= threshold for v in strict.views)
    assert [v.index for v in strict.views] == list(range(len(strict.views)))
    summary = json.loads((Path(strict.root) / "summary.json").read_text())
    assert summary["rejected"]["low_valid"] >= 1 and summary["params"]["min_valid"] == threshold
    assert len(strict.views) == BASE["views"]  # replacements came from the reserve
    for v in strict.views:
        for sub in ("A", "B", "label"):
            assert (Path(strict.root) / sub / v.file).is_file()
    assert sorted(p.name for p in (Path(strict.root) / "A").iterdir()) == [v.file for v in strict.views]
    # as released: the probes turn the view down first, or the render does; either way it is replaced
    probed = process_pair(
        StageContext(cat, settings), 1, PairParams(**BASE, min_valid=threshold * (1 - 1e-9))
    )
    rejected = json.loads((Path(probed.root) / "summary.json").read_text())["rejected"]
    assert rejected.get("low_valid_probe", 0) + rejected.get("low_valid", 0) >= 1, rejected
    assert len(probed.views) == BASE["views"] and all(v.valid >= threshold * (1 - 1e-9) for v in probed.views)
