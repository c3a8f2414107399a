"""The trade report runs from one command and its Pareto front is right."""

from __future__ import annotations

import csv

import pytest

from siteline.cli import main
from siteline.cli.bench import _bench_trade

pareto = _bench_trade().pareto


def test_pareto_front() -> None:
    costs = [1.0, 2.0, 3.0, 1.5, 4.0]
    values = [0.5, 0.7, 0.6, 0.4, 0.9]
    assert pareto(costs, values) == [0, 1, 4]


@pytest.mark.slow  # over 25 s on a 2-core machine: `make test-all` runs it
def test_bench_trade_quick_run(tmp_path, capsys) -> None:
    code = main(
        ["bench", "trade", "--quick", "--views", "2", "--site-density", "2", "--out", str(tmp_path / "t")]
    )
    assert code == 0
    rows = list(csv.DictReader(open(tmp_path / "t" / "trade.csv")))
    assert len(rows) == 8  # 2 scales x 2 point sizes x (fixed disks, world splats)
    assert {r["splat"] for r in rows} == {"fixed", "world"}
    for r in rows:
        assert 0.0 <= float(r["coverage"]) <= 1.0 and 0.0 <= float(r["f1_2d"]) <= 1.0
        assert float(r["seconds_per_view"]) > 0 and float(r["points_read_per_view"]) > 0
    labels = list(csv.DictReader(open(tmp_path / "t" / "labels3d.csv")))
    assert {r["backend"] for r in labels} == {"pykdtree", "ckdtree"}
    assert len({r["accuracy_3d"] for r in labels}) == 1  # the backend changes speed, never the labels
    assert (tmp_path / "t" / "seconds_vs_f1.png").stat().st_size > 1000
    assert "Pareto" in (tmp_path / "t" / "trade.md").read_text()
