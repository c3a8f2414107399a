"""The trade (siteline.trade) runs from the installed command, scores against the analytic truth, and
refuses what it cannot run in one line."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from siteline.errors import ConfigError
from siteline.trade import TradeRow, parse_variant, trade_markdown

SITELINE = Path(sys.executable).with_name("siteline")


def test_variants_are_parsed_and_bad_ones_named() -> None:
    assert parse_variant('r4={"radius_multiplier": 4}') == ("r4", {"radius_multiplier": 4})
    for bad in ("r4", 'r4={"radius_multiplier": 4', "=", "x=[1]"):
        with pytest.raises(ConfigError, match="variant"):
            parse_variant(bad)


def test_the_table_names_the_weakest_object_and_a_failed_variant() -> None:
    scores = {"precision": 0.9, "recall": 0.8, "f1": 0.85, "boundary_f": 0.7, "specks_median": 1.0,
              "scored_share": 0.9, "object_recall": {"jib#21": 0.95, "pole#60": 0.62},
              "false_change": {"shed#10": 0.004, "tree#60": 0.031}, "dropped_share": 0.052,
              "object_views": {"jib#21": 3, "pole#60": 9}, "camera_nearest_m": {"min": 3.2, "p10": 4.0, "median": 9.0},
              "object_through": {"jib#21": 0.02, "pole#60": 0.31}}  # fmt: skip
    rows = [
        TradeRow("default", {}, 10.0, 1.0, 0.3, scores),
        TradeRow("fill 0", {"fill_px": 0}, 8.0, math.nan, 0.3, scores),
        TradeRow("fixed 1 px", {"splat": "fixed"}, error="every view rejected"),
    ]
    md = trade_markdown(rows, "boxes", 40.0)
    assert "synthetic boxes (flown) at 40 points/m2" in md
    assert "cameras:" not in md  # no planned altitude in these scores
    planned = trade_markdown(
        [TradeRow("default", {}, 10.0, 1.0, 0.3, scores | {"planned_altitude": {"altitude_m": 33.8, "why": "clears the 18.8 m jib by 15 m"}})],
        "boxes", 40.0,
    )  # fmt: skip
    assert "The later scene's cameras: planned at 33.8 m (clears the 18.8 m jib by 15 m)." in planned
    assert (
        "| default | release defaults | 0.900 | 0.800 | 0.850 | 0.700 | 1 | pole#60 0.62 | tree#60 3.1% | 5.2% "
        "| 90.0% | jib#21 3 | pole#60 31.0% | 3.20 | 10 | 1.0 s |" in md
    )
    # a row measured before false change, the ignored share, views and cameras were scored says so, not 0
    old = {
        k: v
        for k, v in scores.items()
        if k not in ("false_change", "dropped_share", "object_views", "camera_nearest_m", "object_through")
    }
    assert "| pole#60 0.62 | - | - | 90.0% | - | - | - |" in trade_markdown(
        [TradeRow("old", {}, 10.0, 1.0, 0.3, old)], "site", 10.0, "sampled"
    )
    assert "| fill 0 | fill_px=0 |" in md and md.count("| reused |") == 1
    assert "| fixed 1 px | splat=fixed | no release: every view rejected |" in md
    assert math.isnan(rows[2].seconds)


def test_bench_trade_refuses_a_bad_grid_and_variant_in_one_line(tmp_path) -> None:
    cases = (
        (["--grid", "huge"], "grid 'huge'"),
        (["--variant", "oops"], "variant 'oops'"),
        (["--variant", 'big={"radius_multipler": 4}'], "unknown pair knobs ['radius_multipler']"),
        (["--variant", 'neg={"scale": -1}'], "variant 'neg'"),
    )

    def run(args: list[str]) -> subprocess.CompletedProcess:
        return subprocess.run(
            [str(SITELINE), "bench", "trade", "--out", str(tmp_path), *args], capture_output=True, text=True
        )

    with ThreadPoolExecutor(len(cases)) as pool:  # each a process start-up: run them at once
        procs = list(pool.map(run, [args for args, _ in cases]))
    for (_, words), proc in zip(cases, procs, strict=True):
        assert proc.returncode != 0 and words in proc.stderr + proc.stdout
        assert "Traceback" not in proc.stderr
    assert not any(tmp_path.iterdir())  # nothing made before the refusal


@pytest.mark.slow  # a small 2-epoch site made, ingested and processed twice: about a minute
def test_bench_trade_from_the_installed_command(tmp_path) -> None:
    env = os.environ | {"SITELINE_HOME": str(tmp_path / "unused-home")}
    proc = subprocess.run(
        [str(SITELINE), "bench", "trade", "--layout", "boxes", "--site-density", "8", "--views", "3", "--grid", "quick",
         "--pictures", "1", "--out", str(tmp_path / "t")],
        capture_output=True, text=True, env=env, timeout=600,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    folder = tmp_path / "t" / "boxes-8"
    rows = json.loads((folder / "trade.json").read_text())
    assert [r["variant"] for r in rows] == ["default", "no gap fill"]
    for r in rows:
        assert r["error"] is None and 0 < r["precision"] <= 1 and 0 < r["recall"] <= 1 and r["views"] == 3
        assert r["object_recall"] and all(0 <= v <= 1 for v in r["object_recall"].values())
        # no camera nearer than the views' 3 m clearance to a point of either scene, measured apart
        cams = r["camera_nearest_m"]
        assert 3.0 - 1e-6 <= cams["min"] <= cams["p10"] <= cams["median"]
        assert set(r["object_through"]) == set(r["object_ignored"]) and all(
            0 <= v <= 1 - r["object_ignored"][k] + 1e-9 for k, v in r["object_through"].items()
        )
        assert set(r["object_views"]) <= set(r["object_ignored"]) and all(
            0 <= n <= 3 for n in r["object_views"].values()
        )
    assert "| default | release defaults |" in (folder / "trade.md").read_text()
    # LiDAR only: the cameras were planned, above the crane by the clearance, and the trade says so
    planned = rows[0]["planned_altitude"]
    assert planned["altitude_m"] > 18.8 and "clears" in planned["why"], planned
    assert f"planned at {planned['altitude_m']:g} m" in (folder / "trade.md").read_text()
    assert len(list(folder.glob("*.png"))) == 2
