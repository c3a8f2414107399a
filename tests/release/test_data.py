"""Dataset, metrics against torchmetrics, and the baseline learning."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader

from siteline.data import ChangeDetectionDataset, TrainTransforms
from siteline.errors import ReleaseError
from siteline.release.metrics import confusion, scores


def test_dataset_samples(built) -> None:
    _, _, pub = built
    ds = ChangeDetectionDataset(pub.root, "train")
    assert len(ds) > 0
    s = ds[0]
    assert s["image"].dtype == torch.float32 and s["image"].shape[:2] == (2, 3)
    assert 0.0 <= float(s["image"].min()) and float(s["image"].max()) <= 1.0
    assert s["mask"].dtype == torch.int64 and s["mask"].shape == (1, *s["image"].shape[-2:])
    assert set(torch.unique(s["mask"]).tolist()) <= {0, 1, 255}
    assert [ds[i]["id"] for i in range(len(ds))] == sorted(ds[i]["id"] for i in range(len(ds)))
    assert ds.plot(0).size[0] == 3 * s["image"].shape[-1]


def test_dataloader_with_two_workers(built) -> None:
    _, _, pub = built
    ds = ChangeDetectionDataset(pub.root, "train", TrainTransforms(crop=64, seed=0))
    # spawned workers: forking a process that runs threads (zarr, Prefect) is unsafe
    batches = list(DataLoader(ds, batch_size=2, num_workers=2, multiprocessing_context="spawn"))
    assert sum(len(b["id"]) for b in batches) == len(ds)
    assert batches[0]["image"].shape[1:] == (2, 3, 64, 64) and batches[0]["mask"].shape[1:] == (1, 64, 64)


def test_dataset_errors_name_the_root(tmp_path) -> None:
    with pytest.raises(ReleaseError, match="does not exist"):
        ChangeDetectionDataset(tmp_path / "nope", "train")
    with pytest.raises(ReleaseError, match="manifest.json"):
        ChangeDetectionDataset(tmp_path, "train")
    with pytest.raises(ReleaseError, match="split"):
        ChangeDetectionDataset(tmp_path, "holdout")


def test_metrics_equal_torchmetrics() -> None:
    from torchmetrics.classification import (
        BinaryCohenKappa,
        BinaryF1Score,
        BinaryJaccardIndex,
        BinaryPrecision,
        BinaryRecall,
        MulticlassAccuracy,
        MulticlassJaccardIndex,
    )

    rng = np.random.default_rng(0)
    target = torch.from_numpy(rng.choice([0, 1, 255], size=(4, 64, 64), p=[0.6, 0.25, 0.15]))
    pred = torch.from_numpy(rng.integers(0, 2, (4, 64, 64)))
    s = scores(confusion(pred, target))
    keep = target != 255
    p, t = pred[keep], target[keep]
    assert s.iou_changed == pytest.approx(float(BinaryJaccardIndex()(p, t)), abs=1e-6)
    assert s.miou == pytest.approx(float(MulticlassJaccardIndex(2, average="macro")(p, t)), abs=1e-6)
    assert s.precision == pytest.approx(float(BinaryPrecision()(p, t)), abs=1e-6)
    assert s.recall == pytest.approx(float(BinaryRecall()(p, t)), abs=1e-6)
    assert s.f1 == pytest.approx(float(BinaryF1Score()(p, t)), abs=1e-6)
    assert s.oa == pytest.approx(float(MulticlassAccuracy(2, average="micro")(p, t)), abs=1e-6)
    assert s.kappa == pytest.approx(float(BinaryCohenKappa()(p, t)), abs=1e-6)
    assert s.pixels == int(keep.sum())


def test_baseline_loss_decreases_and_evaluation_cites_the_manifest(built, tmp_path) -> None:
    import hashlib
    import json

    from siteline.baseline import FCSiamDiff, TrainParams, class_weights, evaluate, train

    _, _, pub = built
    ds = ChangeDetectionDataset(pub.root, "train")
    fixed = [ds[i] for i in range(min(4, len(ds)))]
    loss_fn = torch.nn.CrossEntropyLoss(weight=class_weights(pub.root), ignore_index=255)

    @torch.no_grad()
    def fixed_loss(model: torch.nn.Module) -> float:
        # batch statistics (running ones need many iterations to settle), no dropout
        model.train()
        for m in model.modules():
            if isinstance(m, torch.nn.Dropout2d):
                m.eval()
        img = torch.stack([s["image"][..., :128, :160] for s in fixed])
        mask = torch.stack([s["mask"][0, :128, :160] for s in fixed])
        return float(loss_fn(model(img), mask))

    torch.manual_seed(0)
    before = fixed_loss(FCSiamDiff())  # the initial weights train() starts from (same seed)
    log = train(pub.root, tmp_path, TrainParams(max_iters=30, crop=96, seed=0))
    trained = FCSiamDiff()
    trained.load_state_dict(torch.load(tmp_path / "model.pt", weights_only=True)["model"])
    assert fixed_loss(trained) < before
    assert log["iterations"] == 30
    result = evaluate(pub.root, tmp_path / "model.pt", tmp_path / "r.json", "train")
    sha = hashlib.sha256(open(f"{pub.root}/manifest.json", "rb").read()).hexdigest()
    assert result["release"]["manifest_sha256"] == sha
    assert (
        json.loads((tmp_path / "r.json").read_text())["metric_definition"]["name"] == "siteline-cd-metrics/1"
    )
    assert 0.0 <= result["scores"]["miou"] <= 1.0
    # the floor beside it: every pixel predicted unchanged, scored on the same truth
    masks = [ChangeDetectionDataset(pub.root, "train")[i]["mask"][0] for i in range(len(ds))]
    floor = scores(sum(confusion(torch.zeros_like(m), m) for m in masks))
    assert (
        result["trivial_scores"]["miou"] == pytest.approx(floor.miou)
        and result["trivial_scores"]["f1"] == 0.0
    )
    assert result["trivial_scores"]["predicts"] == "all unchanged"
