"""Export profiles: a release laid out as each change-detection toolbox's stock loader expects.

A release stays immutable: an export is a new folder of relative symlinks (or copies) into it, plus
the list files a tool needs and ``siteline-export.json`` saying what was done. Every profile's
``label`` folder holds the LEVIR-CD label (0 unchanged, 255 changed, ignore as 0), the one encoding all
the tools read the same way; each profile names the one setting its tool needs to honour ignore.
The loading rules below were read in each tool's own loader (DESIGN.md §8).
"""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from siteline.errors import ReleaseError
from siteline.release.layout import manifest_format
from siteline.release.manifest import read_manifest
from siteline.stores import publish_folder

SPLITS = ("train", "val", "test")
EXPORT_RECORD = "siteline-export.json"


@dataclass(frozen=True)
class Profile:
    """name: the ``--profile`` value. tool: the loader it targets. label_rule: what that loader does to
    label pixel values. honour_ignore: the one setting that makes the tool honour ignore. split_map:
    release split -> the tool's split. files: (split, item id) -> [(release folder, export path)].
    lists: the list files, path -> lines, from {tool split: [item ids]}."""

    name: str
    tool: str
    label_rule: str
    honour_ignore: str
    files: Callable[[str, str], list[tuple[str, str]]]
    lists: Callable[[dict[str, list[str]]], dict[str, list[str]]] = lambda _: {}
    split_map: tuple[tuple[str, str], ...] = (("train", "train"), ("val", "val"), ("test", "test"))
    forbidden_in_path: str = ""


def _per_split(folders: dict[str, str]) -> Callable[[str, str], list[tuple[str, str]]]:
    return lambda split, item: [(src, f"{split}/{dst}/{item}.png") for src, dst in folders.items()]


PROFILES: dict[str, Profile] = {
    p.name: p
    for p in (
        Profile(
            "opencd",
            "Open-CD LEVIR_CD_Dataset (data_prefix img_path_from=<split>/A, img_path_to=<split>/B, "
            "seg_map_path=<split>/label)",
            "format_seg_map='to_binary' (the default) maps values >= 128 to 1",
            "to honour ignore: format_seg_map=None with seg_map_path='<split>/label_ignore' (0/1/255) and "
            "ignore_index=255 in the decode head's loss",
            _per_split({"A": "A", "B": "B", "label": "label", "label_ignore": "label_ignore"}),
        ),
        Profile(
            "torchgeo-levircd",
            "TorchGeo LEVIRCD(root, split): root/A|B|label/<split>*.png, matched in sorted order",
            "clamp(0, 1) then long",
            "TorchGeo's loader clamps labels to {0, 1} and cannot carry ignore: to honour it, train on "
            "siteline.data.ChangeDetectionDataset(RELEASE, split, image_range=255.0) (mask 0/1/255) with "
            "ChangeDetectionTask(task='multiclass', num_classes=2, ignore_index=255)",
            lambda split, item: [(f, f"{f}/{split}_{item}.png") for f in ("A", "B", "label")],
        ),
        Profile(
            "torchgeo-levircdplus",
            "TorchGeo LEVIRCDPlus(root, split): root/LEVIR-CD+/{train,test}/A|B|label/<name>.png",
            "clamp(0, 1) then long",
            "TorchGeo's loader clamps labels to {0, 1} and cannot carry ignore: to honour it, train on "
            "siteline.data.ChangeDetectionDataset(RELEASE, split, image_range=255.0) (mask 0/1/255) with "
            "ChangeDetectionTask(task='multiclass', num_classes=2, ignore_index=255)",
            lambda split, item: [(f, f"LEVIR-CD+/{split}/{f}/{item}.png") for f in ("A", "B", "label")],
            split_map=(("train", "train"), ("val", "train"), ("test", "test")),
        ),
        Profile(
            "changemamba",
            "ChangeMamba ChangeDetectionDatset(<out>/<split>, names from <out>/<split>_list.txt): T1|T2|GT/<name>",
            "label / 255 (GT 255 -> 1), then long",
            "to honour ignore: read GT_ignore/ (0/1/255) instead of GT/ and drop the division by 255 "
            "(`label = label / 255` in make_data_loader.py), with ignore_index=255 in the loss",
            _per_split({"A": "T1", "B": "T2", "label": "GT", "label_ignore": "GT_ignore"}),
            lists=lambda names: {f"{s}_list.txt": [f"{i}.png" for i in ids] for s, ids in names.items()},
        ),
        Profile(
            "changeformer",
            "ChangeFormer / BIT CDDataset(root_dir, split): A|B|label/<name>, names in list/<split>.txt",
            "label_transform='norm': label // 255",
            "to honour ignore: label_transform=None with ANNOT_FOLDER_NAME='label_ignore' (0/1/255) in "
            "datasets/CD_dataset.py; its cross-entropy already ignores 255",
            lambda split, item: [(f, f"{f}/{item}.png") for f in ("A", "B", "label", "label_ignore")],
            lists=lambda names: {f"list/{s}.txt": [f"{i}.png" for i in ids] for s, ids in names.items()},
        ),
        Profile(
            "torchange",
            "torchange LEVIRCD(dataset_dir=<out>/<split>): A/*.png, with 'A' replaced by 'B' and 'label' "
            "in each path",
            "the evaluator binarises label > 0",
            "to honour ignore: mask the evaluator's pixels with ignore/<name>.png (255 = ignore) or score "
            "predictions with `siteline release score`",
            _per_split({"A": "A", "B": "B", "label": "label", "ignore": "ignore"}),
            forbidden_in_path="A",
        ),
    )
}


@dataclass
class ExportResult:
    profile: str
    out: str
    files: int
    splits: dict[str, int]
    split_map: dict[str, str]
    label_rule: str
    honour_ignore: str

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


def _export_name(profile: Profile, item_id: str) -> str:
    # torchange replaces every 'A' of a path: ids are lower-cased (one site per release: no collision)
    return item_id.lower() if profile.forbidden_in_path else item_id


def _check_export(root: Path, profile: Profile, out: Path, doc: dict[str, Any]) -> None:
    if manifest_format(doc) < 2:
        raise ReleaseError(
            f"release {doc['name']} {doc['version']} is format 1 (label/ holds 0/1/255): rebuild it with this "
            "siteline to export it; format 1 releases stay readable with siteline.data."
        )
    if out.exists() and any(out.iterdir()):
        raise ReleaseError(
            f"export folder {out} is not empty: choose a new folder (an export never overwrites)."
        )
    if profile.forbidden_in_path and profile.forbidden_in_path in str(out):
        raise ReleaseError(
            f"export folder {out} contains {profile.forbidden_in_path!r}: {profile.tool} replaces every "
            f"{profile.forbidden_in_path!r} in a path to find B and label; choose a path without it."
        )


def _plan_files(
    root: Path, profile: Profile, out: Path, doc: dict[str, Any]
) -> tuple[list[tuple[Path, Path]], dict[str, list[str]]]:
    """(release file, export path) for every file, and the item names per tool split."""
    split_map = dict(profile.split_map)
    names: dict[str, list[str]] = {}
    planned: list[tuple[Path, Path]] = []
    for it in sorted(doc["items"], key=lambda it: it["id"]):
        split = split_map[it["split"]]
        name = _export_name(profile, it["id"])
        names.setdefault(split, []).append(name)
        for folder, dest in profile.files(split, name):
            planned.append((root / it["split"] / folder / f"{it['id']}.png", out / dest))
    return planned, names


def _write_files(planned: list[tuple[Path, Path]], out: Path, work: Path, copy: bool) -> None:
    for src, dest in planned:
        if not src.is_file():
            raise ReleaseError(f"{src} is missing: the release is incomplete (`siteline release verify`).")
        target = work / dest.relative_to(out)
        target.parent.mkdir(parents=True, exist_ok=True)
        if copy:
            shutil.copyfile(src, target)
        else:
            # relative to where the link will live once the folder is renamed into place
            os.symlink(os.path.relpath(src, dest.parent), target)


def export_release(root: Path, profile_name: str, out: Path, copy: bool = False) -> ExportResult:
    """Lay out the release at ``root`` for ``profile_name`` in the new folder ``out``: relative
    symlinks into the release (``copy``: copies), list files, and ``siteline-export.json``; built
    beside ``out`` and renamed into place whole."""
    if profile_name not in PROFILES:
        raise ReleaseError(f"unknown export profile {profile_name!r}: use one of {', '.join(PROFILES)}.")
    profile = PROFILES[profile_name]
    root, out = Path(root).resolve(), Path(out).absolute()
    doc = read_manifest(root)
    _check_export(root, profile, out, doc)
    planned, names = _plan_files(root, profile, out, doc)
    result = ExportResult(
        profile.name, str(out), len(planned), {s: len(v) for s, v in sorted(names.items())},
        dict(profile.split_map), profile.label_rule, profile.honour_ignore,
    )  # fmt: skip
    with publish_folder(out) as work:
        _write_files(planned, out, work, copy)
        for rel, lines in profile.lists(names).items():
            (work / rel).parent.mkdir(parents=True, exist_ok=True)
            (work / rel).write_text("".join(f"{line}\n" for line in lines))
        record = result.to_dict() | {
            "release": {"name": doc["name"], "version": doc["version"], "root": str(root)},
            "tool": profile.tool,
            "links": "copies" if copy else "relative symlinks into the release",
        }
        (work / EXPORT_RECORD).write_text(json.dumps(record, indent=1) + "\n")
    return result
