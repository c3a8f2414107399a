"""The change labels measured the way a user meets them: the analytic box scene through the pipeline
with the release defaults, its masks scored against the ray-cast truth (bench/trade.py in small)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from siteline import pipeline
from siteline.catalog import open_catalog
from siteline.catalog.context import StageContext
from siteline.labels.accuracy import accuracy_text, density_of_spacing, measured_for
from siteline.records.params.pairs import PairParams
from siteline.release.datasheet import _radius_lines
from siteline.synth.scoring import score_pair
from siteline.trade import SITE, TradeScene, synthetic_pair


@pytest.mark.slow  # about a minute: a 2-epoch scene ingested and its pair processed twice
def test_default_labels_beat_the_nearest_rule_against_analytic_truth(tmp_path: Path) -> None:
    settings, site_dir, pid = synthetic_pair(tmp_path, TradeScene("boxes", 20.0, views=6))
    cat = open_catalog(settings)
    try:
        base = pipeline.release_parameters(cat, SITE).pair
        assert (base.label_rule, base.min_region_points) == ("adaptive", 3)
        scores = {}
        for name, params in (
            ("default", base),
            ("nearest", replace(base, label_rule="nearest", min_region_points=1)),
        ):
            out = pipeline.process_pairs(StageContext(cat, settings), [pid], params)[pid]
            scores[name] = score_pair(settings.store, out.root, site_dir, (0, 1))
    finally:
        cat.dispose()
    new, old = scores["default"], scores["nearest"]
    specks = sorted(new.specks)[len(new.specks) // 2], sorted(old.specks)[len(old.specks) // 2]
    assert specks[0] * 5 < specks[1], specks
    assert new.precision > old.precision + 0.1, (new.precision, old.precision)
    assert new.recall > 0.75  # 6 views of the LiDAR-only scene at 20 points/m2: 0.79 (2026-11-29)
    # every changed object is found, the thin jib and pole included
    assert set(new.object_recall(200)) >= {"jib#21", "container#40"}
    # the thin jib and pole at 0.54-0.55 here (2026-11-29): issue 67 asks 0.90 (splats at a surface's
    # own spacing, not built); this holds the floor until then
    assert min(new.object_recall(200).values()) > 0.5, new.object_recall(200)


def test_datasheets_quote_the_measurement_nearest_the_pair() -> None:
    assert density_of_spacing(0.1487) == pytest.approx(9.98, abs=0.05)
    assert measured_for("surface", 8, True, 0.15).density == 10  # the synthetic site
    assert measured_for("surface", 8, True, 0.07).density == 40  # the box scene
    assert measured_for("surface", 8, True, 0.015).density == 1000
    assert measured_for("surface", 3, True, 0.15) is None
    assert measured_for("surface", 8, False, 0.15) is None  # not measured without the trim
    assert measured_for("surface", 8, True, 0.15, 0.7).recall > measured_for("surface", 8, True, 0.15).recall
    assert measured_for("surface", 8, True, 0.15, 0.5) is None  # a probe not measured
    # the adaptive rule (the default) was measured on flown epochs, and says so with its two figures
    flown = accuracy_text("adaptive", 3, True, 0.15, 0.7)
    assert flown is not None and "flown epochs" in flown and "at most 1.2% of pixels called changed" in flown
    assert measured_for("adaptive", 3, True, 0.06, 0.7).scene == "sloped scene"  # ~61 points/m2: nearest 80
    assert measured_for("adaptive", 8, True, 0.15, 0.7) is None
    # with unsure edges ignored (the default) its own rows, which say so; without the trim no such rows
    unsure = measured_for("adaptive", 3, True, 0.06, 0.7, True)
    assert unsure is not None and unsure.unsure_edges and unsure.scene == "sloped scene"
    assert measured_for("adaptive", 3, False, 0.06, 0.7, True) is None
    assert "unsure edges" in accuracy_text("adaptive", 3, True, 0.15, 0.7, True)
    # a rule not measured with them quotes its row without them, and says so
    assert "measured before unsure edges were ignored" in accuracy_text("surface", 8, True, 0.15, 0.7, True)
    # sparse surfaces kept (the default) have rows of their own, which say so; a setting measured only
    # without them quotes those rows, saying so
    sparse = measured_for("adaptive", 3, True, 0.06, 0.7, True, True)
    assert sparse is not None and sparse.sparse_surfaces and sparse.recall > unsure.recall
    assert measured_for("adaptive", 3, True, 0.06, 0.7, False, True) == measured_for(
        "adaptive", 3, True, 0.06, 0.7
    )
    assert "sparse surfaces" in accuracy_text("adaptive", 3, True, 0.15, 0.7, True, True)
    older = accuracy_text(
        "surface", 8, True, 0.15, 0.7, True, True
    )  # measured without either: the first named
    assert "measured before unsure edges were ignored" in older and "sparse" not in older
    assert measured_for("nearest", 1, False, 0.15, 0.7) == measured_for("nearest", 1, False, 0.15)  # no probe
    text = accuracy_text("surface", 8, True, 0.15, 0.7)
    assert "precision 0.98" in text and "recall 0.97" in text and "synthetic site at 10 points/m2" in text
    pair = {"id": 1, "radius_m": 0.37, "labels": {"radius_m": 0.37, "radius": {
        "median_spacing_m": {"t1": 0.15, "t2": 0.148}, "multiplier": 2.5,
        "expected_false_change": {"multiplier": 2.5, "per_direction": 0.0131, "union": 0.026},
    }}}  # fmt: skip
    surface = PairParams(label_rule="surface", min_region_points=8, trim_edges=True)
    [line] = _radius_lines([pair], 1.0, surface)
    assert (
        "surface rule" in line
        and "regions under 8 points" in line
        and "measured against analytic truth" in line
    )
    [old] = _radius_lines(
        [pair], 1.0, PairParams(label_rule="nearest", min_region_points=1, trim_edges=False)
    )
    assert "2^(-k^2) per direction" in old and "nearest" not in old.split(";")[0]
