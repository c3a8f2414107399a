"""The committed tiny release (tests/data/tiny_release, made by data.py beside it): dataset and metric
tests that need no pipeline run."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from siteline.data import ChangeDetectionDataset
from siteline.release.manifest import verify_files
from siteline.release.score import score_predictions

HERE = Path(__file__).resolve().parents[1] / "data" / "tiny_release"
TINY = HERE / "release"


def _generator():  # noqa: ANN202
    spec = importlib.util.spec_from_file_location("tiny_release_data", HERE / "data.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_generator_reproduces_the_committed_fixture(tmp_path) -> None:
    out = _generator().generate(tmp_path / "tiny")
    committed = sorted(p.relative_to(TINY) for p in TINY.rglob("*") if p.is_file())
    assert committed == sorted(p.relative_to(out) for p in out.rglob("*") if p.is_file())
    for rel in committed:
        assert (TINY / rel).read_bytes() == (out / rel).read_bytes(), rel
    assert verify_files(TINY) == []


@pytest.mark.parametrize(("split", "n"), [("train", 2), ("val", 1), ("test", 1)])
def test_dataset_samples(split: str, n: int) -> None:
    ds = ChangeDetectionDataset(TINY, split)
    assert len(ds) == n
    s = ds[0]
    assert s["image"].shape == (2, 3, 64, 64) and s["image"].dtype == torch.float32
    assert 0.0 <= float(s["image"].min()) and float(s["image"].max()) <= 1.0
    truth = np.asarray(Image.open(TINY / split / "label_ignore" / f"{s['id']}.png"))
    assert s["mask"].shape == (1, 64, 64) and torch.equal(
        s["mask"][0], torch.from_numpy(truth.astype(np.int64))
    )
    assert set(np.unique(truth)) == {0, 1, 255}


def _write(folder: Path, rule) -> Path:  # noqa: ANN001
    folder.mkdir(parents=True, exist_ok=True)
    for p in (TINY / "test" / "label_ignore").glob("*.png"):
        Image.fromarray(rule(np.asarray(Image.open(p))).astype(np.uint8)).save(folder / p.name)
    return folder


def test_scores_of_known_predictions(tmp_path) -> None:
    perfect = score_predictions(TINY, "test", _write(tmp_path / "p", lambda t: np.where(t == 1, 255, 0)))
    assert perfect["scores"]["f1"] == 1.0 and perfect["scores"]["miou"] == 1.0
    nothing = score_predictions(TINY, "test", _write(tmp_path / "n", lambda t: np.zeros_like(t)))
    (tn, fp), (fn, tp) = nothing["confusion"]
    truth = np.asarray(Image.open(next((TINY / "test" / "label_ignore").glob("*.png"))))
    assert (tn, fn, fp, tp) == (int((truth == 0).sum()), int((truth == 1).sum()), 0, 0)
    s = nothing["scores"]
    assert s["f1"] == 0.0 and s["iou_changed"] == 0.0 and s["iou_unchanged"] == pytest.approx(tn / (tn + fn))
    assert s["miou"] == pytest.approx((tn / (tn + fn)) / 2)


def test_both_metric_conventions_on_hand_made_confusions() -> None:
    from siteline.release.metrics import per_image_scores, scores

    a = np.array([[90, 10], [0, 0]])  # image 1: changed absent from truth, predicted 10 times
    b = np.array([[50, 0], [10, 40]])  # image 2
    c = np.array([[100, 0], [0, 0]])  # image 3: changed absent from truth and prediction: NaN, skipped
    paper = per_image_scores([a, b, c])
    assert paper["iou_unchanged"] == pytest.approx((0.9 + 50 / 60 + 1.0) / 3)
    assert paper["iou_changed"] == pytest.approx((0.0 + 0.8) / 2)  # image 3 has no changed IoU
    assert paper["miou"] == pytest.approx((paper["iou_unchanged"] + paper["iou_changed"]) / 2)
    split = scores(a + b + c)
    assert split.iou_changed == pytest.approx(40 / 60) and split.iou_unchanged == pytest.approx(240 / 260)
    assert abs(split.miou - paper["miou"]) > 0.01  # the conventions differ: say which one a number is
    assert per_image_scores([c])["iou_changed"] is None and per_image_scores([c])["miou"] == 1.0


def test_score_reports_both_conventions(tmp_path) -> None:
    r = score_predictions(TINY, "test", _write(tmp_path / "p", lambda t: np.where(t == 1, 255, 0)))
    assert r["scores_per_image"]["miou"] == 1.0 and r["scores_per_image"]["images"] == 1
    assert "per_image" in r["metric_definition"]
