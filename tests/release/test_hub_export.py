"""The Hugging Face export read by the real ``datasets`` package, with no code of ours: every item's
images equal to the release's, the label 0/1/255, splits and their sizes in the card's YAML header,
shards cut by size, and the export run as a user runs it (the installed executable)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import datasets  # a dev dependency: the export is judged by the real reader
import numpy as np
import pytest
import yaml
from PIL import Image
from sitehelpers import manifest_doc

from siteline.records.release import Manifest
from siteline.release import hub
from siteline.release.export import export_release
from siteline.release.manifest import verify_files

EXE = str(Path(sys.executable).with_name("siteline"))


def _png(path: Path) -> np.ndarray:
    with Image.open(path) as im:
        return np.asarray(im)


def _card(out: Path) -> dict:
    text = (out / "README.md").read_text()
    assert text.startswith("---\n")
    return yaml.safe_load(text.split("---\n")[1])


def test_load_dataset_reads_every_item_as_released(built, tmp_path) -> None:
    _, _, pub = built
    root = Path(pub.root)
    doc = manifest_doc(root)
    out = tmp_path / "hf"
    result = export_release(root, "hf", out, license=hub.HubLicense("cc-by-4.0"))
    # a cache of its own: the machine's HF cache served another build's rows for the same folder name
    ds = datasets.load_dataset(str(out), cache_dir=str(tmp_path / "hf-cache"))
    want = {
        hub.HUB_SPLITS[s]: sorted(it["id"] for it in doc["items"] if it["split"] == s) for s in hub.HUB_SPLITS
    }
    assert {s: sorted(ds[s]["id"]) for s in ds} == {s: ids for s, ids in want.items() if ids}
    assert result.splits == {s: len(ids) for s, ids in want.items() if ids}
    items = {it["id"]: it for it in doc["items"]}
    for split in ds:
        for row in ds[split]:
            it = items[row["id"]]
            folder = root / it["split"]
            assert np.array_equal(np.asarray(row["image_a"]), _png(folder / "A" / f"{it['id']}.png"))
            assert np.array_equal(np.asarray(row["image_b"]), _png(folder / "B" / f"{it['id']}.png"))
            label = np.asarray(row["label"])
            assert np.array_equal(label, _png(folder / "label_ignore" / f"{it['id']}.png"))
            assert set(np.unique(label)) <= {0, 1, 255}
            assert np.array_equal(np.asarray(row["ignore"]) == 255, label == 255)
            preview = np.asarray(row["label_preview"])  # the hub viewer's colours: red changed, white ignore
            assert preview.shape == label.shape + (3,)
            assert (preview[label == 1] == (220, 40, 40)).all() and (preview[label == 255] == 255).all()
            assert (row["split"], row["pair"], row["view"]) == (it["split"], it["pair"], it["view"])
            assert row["valid"] == it["valid"] and (row["width"], row["height"]) == tuple(it["size_px"])
            cam = it["camera"]
            assert (
                row["camera"]["fx"] == cam["fx"]
                and row["camera"]["rotation"] == cam["cam_from_world"]["rotation"]
            )
            assert row["ignore_causes"] == {
                c: pytest.approx(it["ignore"].get(c, 0.0)) for c in row["ignore_causes"]
            }
    header = _card(out)
    assert header["license"] == "cc-by-4.0" and header["task_categories"] == ["image-segmentation"]
    assert {s["name"]: s["num_examples"] for s in header["dataset_info"]["splits"]} == result.splits
    assert "iVISION-2DCD" in (out / "README.md").read_text() and (out / "montage.png").is_file()
    assert not verify_files(root)  # the release is untouched


def test_shards_are_cut_by_size_and_still_load(built, tmp_path, monkeypatch) -> None:
    _, _, pub = built
    root = Path(pub.root)
    doc = manifest_doc(root)
    n_train = sum(it["split"] == "train" for it in doc["items"])
    monkeypatch.setattr(hub, "SHARD_BYTES", 1)  # one item a shard
    out = tmp_path / "hf"
    export_release(root, "hf", out, license=hub.HubLicense("mit"))
    shards = sorted((out / "data").glob("train-*.parquet"))
    assert len(shards) == n_train and shards[-1].name == f"train-{n_train - 1:05d}-of-{n_train:05d}.parquet"
    assert (
        datasets.load_dataset(str(out), split="train", cache_dir=str(tmp_path / "hf-cache")).num_rows
        == n_train
    )


def test_the_executable_exports_and_refuses_a_used_folder(built, tmp_path) -> None:
    settings, _, pub = built
    env = os.environ | {"SITELINE_HOME": str(settings.home), "SITELINE_DATABASE_URL": settings.database_url}
    out = tmp_path / "hf"
    argv = [EXE, "release", "export", "rel", pub.version, "--profile", "hf", "--out", str(out)]
    # a card needs a licence: none, or other without its name and link, is refused in one line
    for extra in (
        [],
        ["--license", "other"],
        ["--license", "other", "--license-name", "x", "--license-link", "ftp://x"],
    ):
        refused = subprocess.run(argv + extra, env=env, capture_output=True, text=True, timeout=300)
        assert refused.returncode == 2 and "licen" in refused.stderr and "Traceback" not in refused.stderr, (
            refused.stderr
        )
        assert not out.exists()
    argv += [
        "--license",
        "other",
        "--license-name",
        "Site Survey Data Licence 1.0",
        "--license-link",
        "https://example.org/sdl",
    ]
    done = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "0 unchanged, 1 changed, 255 ignore" in done.stdout and "load_dataset" in done.stdout
    record = json.loads((out / "siteline-export.json").read_text())
    assert record["profile"] == "hf" and record["shards"]["train"]
    again = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=300)
    assert again.returncode == 2 and "not empty" in again.stderr and "Traceback" not in again.stderr


def test_the_card_is_written_for_the_export_and_its_snippet_runs(built, tmp_path) -> None:
    """What an ML person reads: one title, the data's source (this release is synthetic), splits, label
    meanings, limitations, licence with name and link, citation; nothing of the release's folder
    layout; and the "Use" snippet runs on the export as written (the folder put in)."""
    _, _, pub = built
    out = tmp_path / "hf"
    export_release(
        Path(pub.root),
        "hf",
        out,
        license=hub.HubLicense("other", "Site Survey Data Licence 1.0", "https://example.org/sdl"),
    )
    text = (out / "README.md").read_text()
    header = _card(out)
    assert header["license"] == "other" and header["license_name"] == "Site Survey Data Licence 1.0"
    assert header["license_link"] == "https://example.org/sdl" and "synthetic" in header["tags"]
    body = text.split("---\n", 2)[2]
    assert [ln for ln in body.splitlines() if ln.startswith("# ")] == [f"# rel {pub.version}"]
    for section in (
        "## Use",
        "## Splits",
        "## Fields",
        "## How it was made",
        "## Limitations",
        "## Licence",
        "## Citation",
    ):
        assert section in body, section
    assert (
        "**Synthetic.**" in body
        and "0 unchanged, 1 changed, 255 ignore" in body
        and "https://example.org/sdl" in body
    )
    for stale in ("label/", "A/", "Which folder", "ChangeDetectionDataset", "manifest.json"):
        assert stale not in body, stale
    code = body.split("```python\n", 1)[1].split("```", 1)[0]
    assert 'load_dataset("path/to/this/folder")' in code
    script = tmp_path / "use.py"
    script.write_text(code.replace("path/to/this/folder", str(out)))
    env = os.environ | {"HF_DATASETS_CACHE": str(tmp_path / "hf-cache"), "HF_DATASETS_OFFLINE": "1"}
    ran = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300, env=env)
    assert ran.returncode == 0, ran.stderr
    assert ran.stdout.startswith("rel_p") or ran.stdout.split()[0] in {
        it["id"] for it in manifest_doc(Path(pub.root))["items"]
    }


@pytest.mark.parametrize(
    ("made", "kind"),
    [
        (["siteline synth; DJI Terra (simulated by siteline)"] * 2, "synthetic"),
        (["DJI; DJI Terra", "DJI; DJI Terra"], "surveyed"),
        (["DJI; DJI Terra", None], "unrecorded"),  # a scene ingested before the software was recorded
        (["siteline synth; x", "DJI; DJI Terra"], "unrecorded"),  # a mix is not called either
    ],
)
def test_provenance_is_read_from_what_wrote_the_scenes(made, kind) -> None:
    doc = {"format": "siteline-release/2", "name": "r", "version": "1.0.0", "created": "2026-11-28", "code_version": "0",
           "items": [], "splits": {"train": [], "val": [], "test": []}, "files": [],
           "lineage": {"scenes": [{"id": k, "las_software": m} for k, m in enumerate(made)]}}  # fmt: skip
    assert hub.provenance(Manifest.from_dict(doc))[0] == kind


def test_a_full_destination_is_named_when_pyarrow_says_errno_28_without_a_file(
    built, tmp_path, monkeypatch
) -> None:
    """pyarrow's full-disk error names no file: the export says the destination's disk filled (not
    the home's), and leaves nothing there."""
    import errno

    from siteline.stores.diskspace import disk_full, full_disk_message

    _, _, pub = built

    def full(*a, **k):  # noqa: ANN002, ANN003, ANN202
        raise OSError(errno.ENOSPC, "Error writing bytes to file. Detail: [errno 28] No space left on device")

    monkeypatch.setattr(hub, "export_hf", full)
    out = tmp_path / "elsewhere" / "hf"
    out.parent.mkdir()
    with pytest.raises(OSError) as caught:
        export_release(Path(pub.root), "hf", out, license=hub.HubLicense("cc-by-4.0"))
    assert caught.value.filename == str(out) and disk_full(caught.value)
    line = full_disk_message(caught.value, tmp_path / "home")
    assert f"writing {out}" in line and f"the file system holding {out.parent} has" in line
    assert list(out.parent.iterdir()) == []  # nothing half-written
