"""Release format 2, export profiles read through each toolbox's own loading rules, padding, scoring
anyone's predictions, and a loader that travels."""

from __future__ import annotations

import glob
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image
from sitehelpers import manifest_doc, writable_copy

from siteline.data import ChangeDetectionDataset
from siteline.errors import ReleaseError
from siteline.release.export import PROFILES, export_release
from siteline.release.manifest import file_entries, verify_files, write_manifest
from siteline.release.metrics import confusion, scores
from siteline.release.score import score_predictions


def _png(path: str | Path) -> np.ndarray:
    with Image.open(path) as im:
        return np.asarray(im)


def _truth(root: Path, item: dict) -> np.ndarray:
    return _png(root / item["split"] / "label_ignore" / f"{item['id']}.png")


# Each tool's loader, reduced to its directory contract and label rule as its own code reads them:
# (export root, tool split) -> [(A path, B path, label as the tool decodes it)].
def _opencd(out: Path, split: str):  # mmseg LoadAnnotations + format_seg_map='to_binary'
    names = sorted(os.listdir(out / split / "A"))
    return [
        (out / split / "A" / n, out / split / "B" / n, (_png(out / split / "label" / n) >= 128).astype(int))
        for n in names
    ]


def _torchgeo_levircd(out: Path, split: str):  # LEVIRCD._load_files + _load_target
    a = sorted(glob.glob(os.path.join(out, "A", f"{split}*.png")))
    b = sorted(glob.glob(os.path.join(out, "B", f"{split}*.png")))
    m = sorted(glob.glob(os.path.join(out, "label", f"{split}*.png")))
    return [
        (x, y, torch.clamp(torch.from_numpy(_png(z).copy()), 0, 1).long().numpy())
        for x, y, z in zip(a, b, m, strict=True)
    ]


def _torchgeo_levircdplus(out: Path, split: str):  # LEVIRCDPlus._load_files: train and test only
    base = out / "LEVIR-CD+" / split
    names = sorted(os.path.basename(p) for p in glob.glob(os.path.join(base, "A", "*.png")))
    return [
        (
            base / "A" / n,
            base / "B" / n,
            torch.clamp(torch.from_numpy(_png(base / "label" / n).copy()), 0, 1).long().numpy(),
        )
        for n in names
    ]


def _changemamba(
    out: Path, split: str
):  # ChangeDetectionDataset: T1/T2/GT + name list, imageio float32 / 255
    names = [line.strip() for line in (out / f"{split}_list.txt").read_text().splitlines()]
    base = out / split
    return [
        (
            base / "T1" / n,
            base / "T2" / n,
            (np.array(_png(base / "GT" / n), np.float32) / 255).astype(np.int64),
        )
        for n in names
    ]


def _changeformer(out: Path, split: str):  # CDDataset: list/<split>.txt, label_transform='norm'
    names = np.loadtxt(out / "list" / f"{split}.txt", dtype=str, ndmin=1)
    return [
        (out / "A" / n, out / "B" / n, np.array(Image.open(out / "label" / n), dtype=np.uint8) // 255)
        for n in names
    ]


def _torchange(
    out: Path, split: str
):  # LEVIRCD: A/*.png; B by '/A/' -> '/B/', label by '/A' -> '/label'; > 0
    a = sorted(glob.glob(os.path.join(out, split, "A", "*.png")))
    return [(p, p.replace("/A/", "/B/"), (_png(p.replace("/A", "/label")) > 0).astype(int)) for p in a]


# tools whose stock loader reads ignore as their loss's ignore index (255), not as unchanged
IGNORE_AWARE = {"changemamba"}


LOADERS = {
    "opencd": _opencd,
    "torchgeo-levircd": _torchgeo_levircd,
    "torchgeo-levircdplus": _torchgeo_levircdplus,
    "changemamba": _changemamba,
    "changeformer": _changeformer,
    "torchange": _torchange,
}


def test_every_profile_has_a_loader_test() -> None:
    assert set(LOADERS) == set(PROFILES)


@pytest.mark.parametrize("profile", sorted(PROFILES))
def test_export_is_read_right_by_the_tools_own_rules(built, tmp_path, profile) -> None:
    _, _, pub = built
    root = Path(pub.root)
    doc = manifest_doc(root)
    out = tmp_path / "export" / profile
    result = export_release(root, profile, out)
    by_split: dict[str, list[dict]] = {}
    split_map = result.split_map
    for it in doc["items"]:
        by_split.setdefault(split_map[it["split"]], []).append(it)
    assert sum(len(v) for v in by_split.values()) == len(doc["items"])
    for split, items in by_split.items():
        samples = LOADERS[profile](out, split)
        assert len(samples) == len(items), (split, len(samples), len(items))
        for (a, b, label), it in zip(samples, sorted(items, key=lambda i: i["id"]), strict=True):
            truth = _truth(root, it)
            assert np.array_equal(_png(a), _png(root / it["split"] / "A" / f"{it['id']}.png"))
            assert np.array_equal(_png(b), _png(root / it["split"] / "B" / f"{it['id']}.png"))
            valid = truth != 255
            assert np.array_equal(label[valid], truth[valid])  # the truth on valid pixels
            # ignored pixels never read as changed: as unchanged, or as the tool's own ignore index
            assert np.all(label[~valid] == (255 if profile in IGNORE_AWARE else 0))
    record = json.loads((out / "siteline-export.json").read_text())
    assert record["profile"] == profile and record["honour_ignore"]
    assert not verify_files(root)  # the release is untouched


def test_export_prints_the_setting_and_refuses_a_used_folder(built, tmp_path, capsys, monkeypatch) -> None:
    from sitehelpers import run_cli

    settings, _, pub = built
    monkeypatch.setenv("SITELINE_HOME", str(settings.home))
    monkeypatch.setenv("SITELINE_DATABASE_URL", settings.database_url)
    out = tmp_path / "ocd"
    code, stdout, err = run_cli(
        capsys, "release", "export", "rel", pub.version, "--profile", "opencd", "--out", str(out)
    )
    assert code == 0, err
    assert "format_seg_map=None" in stdout and "label_ignore" in stdout
    code, _, err = run_cli(
        capsys, "release", "export", "rel", pub.version, "--profile", "opencd", "--out", str(out)
    )
    assert code == 2 and "not empty" in err
    code, _, err = run_cli(
        capsys, "release", "export", "rel", pub.version, "--profile", "nosuch", "--out", str(tmp_path / "x")
    )
    assert code == 2 and "unknown export profile" in err
    a_file = tmp_path / "taken.txt"
    a_file.write_text("mine")
    code, _, err = run_cli(
        capsys, "release", "export", "rel", pub.version, "--profile", "opencd", "--out", str(a_file)
    )
    assert code == 2 and "is a file" in err and "Traceback" not in err and a_file.read_text() == "mine"
    bad = tmp_path / "Alice"
    code, _, err = run_cli(
        capsys, "release", "export", "rel", pub.version, "--profile", "torchange", "--out", str(bad)
    )
    assert code == 2 and "torchange rewrites '/A'" in err and not bad.exists()
    fine = tmp_path / "DATA" / "tc"  # a capital A elsewhere in a name is fine for torchange
    code, stdout, err = run_cli(
        capsys, "release", "export", "rel", pub.version, "--profile", "torchange", "--out", str(fine)
    )
    assert code == 0, err


def test_format_2_folders_agree_and_the_loader_reads_0_1_255(built) -> None:
    _, _, pub = built
    root = Path(pub.root)
    doc = manifest_doc(root)
    assert doc["format"] == 2 and set(doc["layout"]["folders"]) == {
        "A",
        "B",
        "label",
        "ignore",
        "label_ignore",
    }
    for split in ("train", "val", "test"):
        ds = ChangeDetectionDataset(root, split)
        for i in range(len(ds)):
            s = ds[i]
            it = next(x for x in doc["items"] if x["id"] == s["id"])
            aware = _truth(root, it)
            assert np.array_equal(s["mask"][0].numpy(), aware)
            assert set(np.unique(aware)) <= {0, 1, 255}
            levir = _png(root / split / "label" / f"{s['id']}.png")
            ignore = _png(root / split / "ignore" / f"{s['id']}.png")
            assert np.array_equal(levir, np.where(aware == 1, 255, 0))
            assert np.array_equal(ignore, np.where(aware == 255, 255, 0))


def test_images_are_padded_to_multiples_of_32_and_recorded(built) -> None:
    _, _, pub = built
    root = Path(pub.root)
    doc = manifest_doc(root)
    assert doc["layout"]["padding"]["enabled"] and doc["layout"]["padding"]["multiple_px"] == 32
    for it in doc["items"]:
        w, h = it["size_px"]
        pw, ph = it["padded_px"]
        assert (pw, ph) == (352, 256) and (w, h) == (330, 248)  # 660 x 495 photos at scale 0.5
        arrays = {f: _png(root / it["split"] / f / f"{it['id']}.png") for f in doc["layout"]["folders"]}
        for f, arr in arrays.items():
            assert arr.shape[:2] == (ph, pw)
            pad_fill = doc["layout"]["padding"]["fill"][f]
            assert (arr[h:] == pad_fill).all() and (arr[:, w:] == pad_fill).all(), f
        assert (arrays["label_ignore"][:h, :w] != 255).any()  # the rendered part is not all padding


def _predictions(root: Path, split: str, out: Path, rule) -> Path:  # noqa: ANN001
    out.mkdir(parents=True, exist_ok=True)
    for it in manifest_doc(root)["items"]:
        if it["split"] == split:
            Image.fromarray(rule(_truth(root, it)).astype(np.uint8)).save(out / f"{it['id']}.png")
    return out


def test_score_a_perfect_prediction_and_a_known_confusion(built, tmp_path) -> None:
    _, _, pub = built
    root = Path(pub.root)
    perfect = _predictions(root, "test", tmp_path / "perfect", lambda t: np.where(t == 1, 255, 0))
    r = score_predictions(root, "test", perfect)
    assert r["scores"]["f1"] == 1.0 and r["scores"]["miou"] == 1.0 and r["confusion"][0][1] == 0
    # predict "changed" everywhere (0/1 encoding): tp = changed, fp = unchanged, no tn, no fn
    everything = _predictions(root, "test", tmp_path / "all", lambda t: np.ones_like(t))
    r = score_predictions(root, "test", everything)
    (tn, fp), (fn, tp) = r["confusion"]
    assert tn == 0 and fn == 0 and tp > 0 and fp > 0
    assert r["scores"]["precision"] == pytest.approx(tp / (tp + fp))
    assert r["scores"]["iou_unchanged"] == 0.0 and r["scores"]["iou_changed"] == pytest.approx(tp / (tp + fp))
    assert r["scores"]["f1"] == pytest.approx(2 * tp / (2 * tp + fp))


def test_score_names_missing_and_mis_sized_files(built, tmp_path, capsys, monkeypatch) -> None:
    from sitehelpers import run_cli

    settings, _, pub = built
    root = Path(pub.root)
    preds = _predictions(root, "test", tmp_path / "p", lambda t: np.where(t == 1, 255, 0))
    victim = sorted(preds.glob("*.png"))[0]
    monkeypatch.setenv("SITELINE_HOME", str(settings.home))
    monkeypatch.setenv("SITELINE_DATABASE_URL", settings.database_url)
    code, stdout, err = run_cli(
        capsys, "release", "score", "rel", pub.version, "--pred", str(preds), "--json"
    )
    assert code == 0, err
    assert json.loads(stdout)["scores"]["f1"] == 1.0
    Image.fromarray(np.zeros((10, 10), np.uint8)).save(victim)
    code, _, err = run_cli(capsys, "release", "score", "rel", pub.version, "--pred", str(preds))
    assert code == 2 and victim.name in err and "10 x 10" in err
    victim.unlink()
    code, _, err = run_cli(capsys, "release", "score", "rel", pub.version, "--pred", str(preds))
    assert code == 2 and victim.name in err and "lacks 1 of" in err


def test_metrics_when_a_class_is_absent() -> None:
    t = torch.zeros(4, 4, dtype=torch.long)
    s = scores(confusion(t, t))  # all unchanged, predicted perfectly: changed is absent from both
    assert s.iou_changed is None and s.iou_unchanged == 1.0 and s.miou == 1.0
    import torchmetrics

    tm = torchmetrics.classification.MulticlassJaccardIndex(num_classes=2, average="macro")
    assert float(tm(t.flatten(), t.flatten())) == pytest.approx(s.miou)
    p = t.clone()
    p[0, 0] = 1  # one false alarm: changed now present in the prediction
    s = scores(confusion(p, t))
    assert (
        s.iou_changed == 0.0
        and s.iou_unchanged == pytest.approx(15 / 16)
        and s.miou == pytest.approx(15 / 32)
    )


def test_format_1_release_stays_readable_and_verifiable(built, tmp_path) -> None:
    _, _, pub = built
    old = writable_copy(pub.root, tmp_path / "old")
    doc = manifest_doc(old)
    for split in ("train", "val", "test"):
        if (old / split).exists():
            shutil.rmtree(old / split / "label")
            os.replace(old / split / "label_ignore", old / split / "label")  # format 1: 0/1/255 in label/
            shutil.rmtree(old / split / "ignore")
    doc["format"] = "siteline-release/1"
    doc.pop("layout")
    doc["files"] = file_entries(old)
    write_manifest(old, doc)
    assert not verify_files(old)
    new, legacy = ChangeDetectionDataset(pub.root, "train"), ChangeDetectionDataset(old, "train")
    assert len(new) == len(legacy) > 0
    assert torch.equal(new[0]["mask"], legacy[0]["mask"])
    with pytest.raises(ReleaseError, match="format 1"):
        export_release(old, "opencd", tmp_path / "x")


def test_images_as_0_255_floats(built) -> None:
    _, _, pub = built
    a, b = (
        ChangeDetectionDataset(pub.root, "train"),
        ChangeDetectionDataset(pub.root, "train", image_range=255.0),
    )
    assert torch.allclose(a[0]["image"] * 255.0, b[0]["image"], atol=1e-4)
    assert b[0]["image"].max() > 1.0


def test_importing_the_loader_does_not_import_the_catalog() -> None:
    code = "import sys, siteline.data, siteline.release.metrics; print('sqlalchemy' in sys.modules, 'prefect' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "False"]
