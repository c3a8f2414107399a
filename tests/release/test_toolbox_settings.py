"""The settings an export prints are settings that run, checked against each toolbox's own code (read
from its repository at the revision named; the toolboxes themselves cannot be installed here: TorchGeo
needs a torchvision build of this torch, and none exists for the CPU wheel), and predictions saved
under any export's names, or at a tool's resized size, are scored."""

from __future__ import annotations

import ast
import json
import re
from pathlib import Path

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from PIL import Image
from torch import nn

from siteline.data import ChangeDetectionDataset
from siteline.errors import ReleaseError
from siteline.release.export import PROFILES, export_release
from siteline.release.score import score_predictions


def _task_kwargs(profile: str) -> dict:
    """The keyword arguments of ChangeDetectionTask(...) as the export prints them."""
    text = PROFILES[profile].honour_ignore
    call = re.search(r"ChangeDetectionTask\((.*?)\)", text).group(1)
    return {kw.arg: ast.literal_eval(kw.value) for kw in ast.parse(f"f({call})").body[0].value.keywords}


class TorchGeoChangeTask(nn.Module):
    """TorchGeo's ChangeDetectionTask reduced to its loss and its training step
    (torchgeo/trainers/change.py at 7ea0616, configure_losses and _shared_step): CrossEntropyLoss with
    the ignore index for 'ce', BCEWithLogitsLoss for 'bce'; images (B, T, C, H, W) concatenated over
    time for the non-Siamese models; a multiclass target squeezed to (B, H, W), cast to float for 'bce'.
    The model is a small FCN with TorchGeo's input and output shapes."""

    def __init__(self, task: str = "binary", num_classes: int | None = None, ignore_index: int | None = None,
                 loss: str = "bce", in_channels: int = 3) -> None:  # fmt: skip
        super().__init__()
        self.task, self.loss = task, loss
        classes = num_classes or 1
        self.model = nn.Sequential(
            nn.Conv2d(in_channels * 2, 8, 3, padding=1), nn.ReLU(), nn.Conv2d(8, classes, 1)
        )
        if loss == "ce":
            self.criterion: nn.Module = nn.CrossEntropyLoss(
                ignore_index=-1000 if ignore_index is None else ignore_index
            )
        elif loss == "bce":
            self.criterion = nn.BCEWithLogitsLoss()
        else:
            raise ValueError(loss)

    def training_step(self, batch: dict) -> torch.Tensor:
        x, y = batch["image"], batch["mask"]
        x = x.flatten(1, 2)  # rearrange 'b t c h w -> b (t c) h w'
        if self.task == "multiclass":
            y = y.squeeze(1)
        y_hat = self.model(x)
        if self.loss == "bce":
            y = y.float()
        return self.criterion(y_hat, y)


def test_the_torchgeo_setting_trains_one_step_and_the_default_loss_does_not(built) -> None:
    _, _, pub = built
    ds = ChangeDetectionDataset(pub.root, "train", image_range=255.0)
    batch = {k: torch.stack([ds[i][k] for i in range(2)]) for k in ("image", "mask")}
    kwargs = _task_kwargs("torchgeo-levircd")
    assert kwargs == _task_kwargs("torchgeo-levircdplus") and kwargs["loss"] == "ce"
    task = TorchGeoChangeTask(**kwargs)
    opt = torch.optim.SGD(task.parameters(), lr=0.01)
    loss = task.training_step(batch)
    loss.backward()
    opt.step()
    assert torch.isfinite(loss) and all(
        p.grad is not None and torch.isfinite(p.grad).all() for p in task.parameters()
    )
    # ignore pixels do not count: a task whose every valid pixel is right has no loss from them
    assert (batch["mask"] == 255).any()
    without_loss = {k: v for k, v in kwargs.items() if k != "loss"}  # what the export used to print
    with pytest.raises(ValueError, match="Target size .* must be the same as input size"):
        TorchGeoChangeTask(**without_loss).training_step(batch)


def test_changemamba_reads_ignore_as_its_ignore_index_with_stock_settings(built, tmp_path) -> None:
    """ChangeMamba (changedetection/datasets/change_detection.py at 9ce9cec) reads GT as float32 and
    divides by 255; tasks/bcd.py trains with cross_entropy(..., ignore_index=255): the export's 16-bit
    GT carries ignore through that with no code edit."""
    _, _, pub = built
    root = Path(pub.root)
    out = export_release(root, "changemamba", tmp_path / "cm")
    assert "nothing to change" in out.honour_ignore
    name = (tmp_path / "cm" / "train_list.txt").read_text().split()[0]
    label = torch.from_numpy(
        np.array(Image.open(tmp_path / "cm" / "train" / "GT" / name), np.float32) / 255
    ).long()
    truth = np.asarray(Image.open(root / "train" / "label_ignore" / name))
    assert np.array_equal(label.numpy(), truth)  # 0 / 1 / 255 exactly
    logits = torch.zeros(1, 2, *label.shape)
    logits[0, 1][label == 1] = 10.0  # right on every valid pixel, anything on ignore
    logits[0, 0][label == 0] = 10.0
    logits[0, 1][label == 255] = 1e4
    assert F.cross_entropy(logits, label[None], ignore_index=255) < 1e-3


def test_predictions_under_export_names_and_resized_ones_are_scored(
    built, tmp_path, capsys, monkeypatch
) -> None:
    from sitehelpers import manifest_doc, run_cli

    settings, _, pub = built
    root = Path(pub.root)
    items = [it for it in manifest_doc(root)["items"] if it["split"] == "test"]
    truth = {
        it["id"]: np.asarray(Image.open(root / "test" / "label_ignore" / f"{it['id']}.png")) for it in items
    }
    perfect = {i: np.where(t == 1, 255, 0).astype(np.uint8) for i, t in truth.items()}
    for profile, name in (("torchange", lambda i: i.lower()), ("torchgeo-levircd", lambda i: f"test_{i}")):
        folder = tmp_path / profile
        folder.mkdir()
        for i, arr in perfect.items():
            Image.fromarray(arr).save(folder / f"{name(i)}.png")
        assert score_predictions(root, "test", folder)["scores"]["f1"] == 1.0, profile
    record = json.loads(
        (
            export_release(root, "torchange", tmp_path / "tc").out
            and (tmp_path / "tc" / "siteline-export.json")
        ).read_text()
    )
    assert record["names"] == {i.lower(): i for i in sorted(record["names"].values())}
    # ChangeFormer predicts at 256 x 256: scored at that declared size, brought back by nearest neighbour
    squashed = tmp_path / "cf"
    squashed.mkdir()
    for i, arr in perfect.items():
        Image.fromarray(arr).resize((256, 256), Image.Resampling.NEAREST).save(squashed / f"{i}.png")
    monkeypatch.setenv("SITELINE_HOME", str(settings.home))
    monkeypatch.setenv("SITELINE_DATABASE_URL", settings.database_url)
    code, _, err = run_cli(capsys, "release", "score", "rel", pub.version, "--pred", str(squashed))
    assert code == 2 and "--pred-size" in err
    code, out, err = run_cli(
        capsys,
        "release",
        "score",
        "rel",
        pub.version,
        "--pred",
        str(squashed),
        "--pred-size",
        "256x256",
        "--json",
    )
    assert code == 0, err and json.loads(out)["scores"]["f1"] > 0.9
    code, out, _ = run_cli(
        capsys,
        "release",
        "export",
        "rel",
        pub.version,
        "--profile",
        "changeformer",
        "--out",
        str(tmp_path / "cfx"),
    )
    assert code == 0 and "--pred-size 256x256" in out
    with pytest.raises(ReleaseError, match="WIDTHxHEIGHT"):
        from siteline.release.score import parse_size

        parse_size("256")
