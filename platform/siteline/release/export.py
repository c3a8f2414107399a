"""Export profiles: a release laid out as each change-detection toolbox's stock loader expects.

A release stays immutable: an export is a new folder of relative symlinks (or copies) into it, plus
the list files a tool needs and ``siteline-export.json`` saying what was done. Every profile's
``label`` folder holds the LEVIR-CD label (0 unchanged, 255 changed, ignore as 0), the one encoding all
the tools read the same way; each profile names the one setting its tool needs to honour ignore.
The loading rules below were read in each tool's own loader (DESIGN.md §8).
"""

from __future__ import annotations

import errno
import json
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from PIL import Image

from siteline.errors import ReleaseError
from siteline.records.release import Manifest
from siteline.release.hub import HubLicense, Shards
from siteline.release.layout import manifest_format
from siteline.release.manifest import SAFE_ITEM_ID, read_manifest
from siteline.schema import JSON
from siteline.stores import publish_folder

SPLITS = ("train", "val", "test")
EXPORT_RECORD = "siteline-export.json"


@dataclass(frozen=True)
class Profile:
    """name: the ``--profile`` value. tool: the loader it targets. label_rule: what that loader does to
    label pixel values. honour_ignore: the one setting that makes the tool honour ignore (or why none
    is needed). stem: (tool split, item id) -> the file name stem the tool sees (predictions saved
    under it are scored too). files: (tool split, stem) -> [(source, export path)], where a source is
    a release folder linked (or copied) or a derived label (:data:`DERIVED`) written anew. lists: the
    list files, path -> lines, from {tool split: [stems]}. split_map: release split -> the tool's
    split. check_paths: refuses an export folder the tool's path rewriting would break. note: what
    else the user must know (printed at export)."""

    name: str
    tool: str
    label_rule: str
    honour_ignore: str
    files: Callable[[str, str], list[tuple[str, str]]]
    stem: Callable[[str, str], str] = lambda split, item: item
    lists: Callable[[dict[str, list[str]]], dict[str, list[str]]] = lambda _: {}
    split_map: tuple[tuple[str, str], ...] = (("train", "train"), ("val", "val"), ("test", "test"))
    check_paths: Callable[[Path, list[Path]], None] = lambda out, a_paths: None
    note: str = ""


def _per_split(folders: dict[str, str]) -> Callable[[str, str], list[tuple[str, str]]]:
    return lambda split, stem: [(src, f"{split}/{dst}/{stem}.png") for src, dst in folders.items()]


def _changemamba_gt(label_ignore: np.ndarray) -> np.ndarray:
    """ChangeMamba's GT as a 16-bit PNG: 0 unchanged, 255 changed, 65025 ignore, so that its stock
    ``label / 255`` gives 0 / 1 / 255 and its loss and evaluator (ignore_index 255) skip ignore."""
    out = np.zeros(label_ignore.shape, np.uint16)
    out[label_ignore == 1] = 255
    out[label_ignore == 255] = 255 * 255
    return out


# sources an export writes anew from the release's ignore-aware label (the release is never touched)
DERIVED: dict[str, Callable[[np.ndarray], np.ndarray]] = {"changemamba-gt": _changemamba_gt}


def _torchange_paths(out: Path, a_paths: list[Path]) -> None:
    """torchange's LEVIRCD finds B and label by ``path.replace('/A/', '/B/')`` and
    ``path.replace('/A', '/label')`` over the whole path (torchange/data/levircd.py): refuse an export
    folder where that lands anywhere but the A folder itself."""
    for a in a_paths:
        text, want_b, want_label = (
            str(a),
            str(a.parent.parent / "B" / a.name),
            str(a.parent.parent / "label" / a.name),
        )
        if text.replace("/A/", "/B/") != want_b or text.replace("/A", "/label") != want_label:
            raise ReleaseError(
                f"export folder {out}: torchange rewrites '/A' in the whole path {text} to find its label, and "
                "this path holds '/A' elsewhere (a folder whose name starts with A). Choose a path without one."
            )


TORCHGEO_TASK = (
    "siteline.data.dataset.ChangeDetectionDataset(RELEASE, split, image_range=255.0) (mask 0/1/255) with "
    "ChangeDetectionTask(task='multiclass', num_classes=2, ignore_index=255, loss='ce')"
)

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
            + TORCHGEO_TASK
            + " (the default loss='bce' cannot take a multiclass ignore_index: its targets do not fit)",
            lambda split, stem: [(f, f"{f}/{stem}.png") for f in ("A", "B", "label")],
            stem=lambda split, item: f"{split}_{item}",
        ),
        Profile(
            "torchgeo-levircdplus",
            "TorchGeo LEVIRCDPlus(root, split): root/LEVIR-CD+/{train,test}/A|B|label/<name>.png",
            "clamp(0, 1) then long",
            "TorchGeo's loader clamps labels to {0, 1} and cannot carry ignore: to honour it, train on "
            + TORCHGEO_TASK,
            lambda split, stem: [(f, f"LEVIR-CD+/{split}/{f}/{stem}.png") for f in ("A", "B", "label")],
            split_map=(("train", "train"), ("val", "train"), ("test", "test")),
        ),
        Profile(
            "changemamba",
            "ChangeMamba ChangeDetectionDataset(<out>/<split>, names from <out>/<split>_list.txt): T1|T2|GT/<name>",
            "GT / 255 then long: GT holds 0 / 255 / 65025 (16-bit), read as 0 unchanged, 1 changed, 255 ignore "
            "(this layout has no label/ folder)",
            "ignore is honoured with stock settings, nothing to change: its cross-entropy and Lovasz losses "
            "(changedetection/tasks/bcd.py) and its evaluator skip 255",
            _per_split({"A": "T1", "B": "T2", "changemamba-gt": "GT"}),
            lists=lambda names: {f"{s}_list.txt": [f"{i}.png" for i in ids] for s, ids in names.items()},
        ),
        Profile(
            "changeformer",
            "ChangeFormer / BIT CDDataset(root_dir, split): A|B|label/<name>, names in list/<split>.txt",
            "label_transform='norm': label // 255",
            "to honour ignore: label_transform=None with ANNOT_FOLDER_NAME='label_ignore' (0/1/255) in "
            "datasets/CD_dataset.py; its cross-entropy already ignores 255",
            lambda split, stem: [(f, f"{f}/{stem}.png") for f in ("A", "B", "label", "label_ignore")],
            lists=lambda names: {f"list/{s}.txt": [f"{i}.png" for i in ids] for s, ids in names.items()},
            note="ChangeFormer resizes every pair to img_size x img_size (256 by default), squashing these "
            "non-square images; score its predictions at that size with `siteline release score ... "
            "--pred-size 256x256` (img_size=None does not help: it resizes labels to width x width)",
        ),
        Profile(
            "torchange",
            "torchange LEVIRCD(dataset_dir=<out>/<split>): A/*.png, B and label found by rewriting '/A/' and "
            "'/A' in each path",
            "the evaluator binarises label > 0",
            "torchange's loss cannot skip ignore: it trains on label/, where ignore is written as unchanged "
            "(0); its metrics honour ignore only if you mask the evaluator's pixels with ignore/<name>.png "
            "(255 = ignore), or score predictions with `siteline release score`",
            _per_split({"A": "A", "B": "B", "label": "label", "ignore": "ignore"}),
            # lower case, so no file name starts with 'A' (one site per release: no collision)
            stem=lambda split, item: item.lower(),
            check_paths=_torchange_paths,
        ),
    )
}


def prediction_names(split: str, item_id: str) -> list[str]:
    """Every file name a prediction of item ``item_id`` in ``split`` may carry: its id, or the name any
    export profile gives it (``release score`` accepts each)."""
    names = [f"{item_id}.png"]
    for profile in PROFILES.values():
        name = f"{profile.stem(dict(profile.split_map)[split], item_id)}.png"
        if name not in names:
            names.append(name)
    return names


@dataclass
class ExportResult:
    profile: str
    out: str
    files: int
    splits: dict[str, int]
    split_map: dict[str, str]
    label_rule: str
    honour_ignore: str
    note: str = ""
    names: dict[str, str] = field(default_factory=dict)

    def to_dict(self) -> dict[str, JSON]:
        return dict(self.__dict__)


def _check_export(root: Path, out: Path, doc: Manifest, protected: Path | None) -> None:
    """Refuse an export that could not be read or would write where it must not: inside a release
    (resolved, so a symlink or '..' cannot hide it), over a file or a non-empty folder."""
    real = Path(os.path.realpath(out))
    for inside in (root, protected):
        if inside is not None and real.is_relative_to(os.path.realpath(inside)):
            raise ReleaseError(
                f"export folder {out} is inside {inside}: a release is never written into; choose a folder "
                "outside the releases."
            )
    if out.exists() and not out.is_dir():
        raise ReleaseError(f"export folder {out} is a file: choose a new folder.")
    bad = [it.id for it in doc.items if not SAFE_ITEM_ID.fullmatch(it.id)]
    if bad:
        raise ReleaseError(
            f"release {doc.title}: item id {bad[0]!r} is not a file name; the manifest was "
            "edited (`siteline release verify`). Nothing was written."
        )
    if manifest_format(doc) < 2:
        raise ReleaseError(
            f"release {doc.title} is format 1 (label/ holds 0/1/255): rebuild it with this "
            "siteline to export it; format 1 releases stay readable with siteline.data."
        )
    if out.exists() and any(out.iterdir()):
        raise ReleaseError(
            f"export folder {out} is not empty: choose a new folder (an export never overwrites)."
        )


def _plan_files(
    root: Path, profile: Profile, out: Path, doc: Manifest
) -> tuple[list[tuple[str, Path, Path]], dict[str, list[str]], dict[str, str]]:
    """(source, release file, export path) for every file, the stems per tool split, and stem -> item id."""
    split_map = dict(profile.split_map)
    names: dict[str, list[str]] = {}
    ids: dict[str, str] = {}
    planned: list[tuple[str, Path, Path]] = []
    for it in sorted(doc.items, key=lambda it: it.id):
        split = split_map[it.split]
        stem = profile.stem(split, it.id)
        names.setdefault(split, []).append(stem)
        ids[stem] = it.id
        for source, dest in profile.files(split, stem):
            folder = "label_ignore" if source in DERIVED else source
            planned.append((source, root / it.split / folder / f"{it.id}.png", out / dest))
    return planned, names, ids


def _write_files(planned: list[tuple[str, Path, Path]], out: Path, work: Path, copy: bool) -> None:
    for source, src, dest in planned:
        if not src.is_file():
            raise ReleaseError(f"{src} is missing: the release is incomplete (`siteline release verify`).")
        target = work / dest.relative_to(out)
        target.parent.mkdir(parents=True, exist_ok=True)
        if source in DERIVED:
            with Image.open(src) as im:
                Image.fromarray(DERIVED[source](np.asarray(im))).save(target, format="PNG")
        elif copy:
            shutil.copyfile(src, target)
        else:
            # relative to where the link will live once the folder is renamed into place
            os.symlink(os.path.relpath(src, dest.parent), target)


HF_PROFILE = "hf"
HF_LOADER = (
    "datasets.load_dataset(<out>): parquet shards data/<split>-*.parquet and README.md (the hub's card)"
)
PROFILE_NAMES = (*PROFILES, HF_PROFILE)


def _export_hf(root: Path, out: Path, doc: Manifest, license: HubLicense | None) -> ExportResult:
    from siteline.release.hub import export_hf

    if license is None:
        raise ReleaseError(
            "the hf export needs a licence for its card: --license with a hub licence id (cc-by-4.0, mit, ...), "
            "or --license other with --license-name and --license-link."
        )
    try:
        with publish_folder(out) as work:
            return _write_hf(root, out, work, doc, license, export_hf(root, doc, work, license))
    except OSError as exc:
        if exc.errno in (errno.ENOSPC, errno.EDQUOT) and not exc.filename:
            # pyarrow says errno 28 without a file: the disk that filled is the destination's
            raise OSError(exc.errno, exc.strerror or os.strerror(exc.errno), str(out)) from exc
        raise


def _write_hf(
    root: Path, out: Path, work: Path, doc: Manifest, license: HubLicense, shards: Shards
) -> ExportResult:
    """The hf export's record, written beside its shards in ``work``."""
    from siteline.release.hub import HUB_SPLITS

    result = ExportResult(
            HF_PROFILE, str(out), sum(len(v) for v in shards.files.values()), shards.rows,
            dict(HUB_SPLITS), "label holds 0 unchanged, 1 changed, 255 ignore (from label_ignore/)",
            "ignore is carried: train with ignore_index=255 on the label field (or mask with the ignore field)",
            f"load it with datasets.load_dataset({str(out)!r}); licence in the card: {license.id}",
    )  # fmt: skip
    record = result.to_dict() | {
        "release": {"name": doc.name, "version": doc.version, "root": str(root)},
        "tool": HF_LOADER, "links": "images copied into the parquet shards", "shards": shards.files,
    }  # fmt: skip
    (work / EXPORT_RECORD).write_text(json.dumps(record, indent=1) + "\n")
    return result


def export_release(
    root: Path, profile_name: str, out: Path, copy: bool = False, protected: Path | None = None,
    license: HubLicense | None = None,
) -> ExportResult:  # fmt: skip
    """Lay out the release at ``root`` for ``profile_name`` in the new folder ``out``: relative
    symlinks into the release (``copy``: copies; derived labels are written anew), list files, and
    ``siteline-export.json`` (with the file names given, stem -> item id); built beside ``out`` and
    renamed into place whole. ``out`` may not resolve inside the release or inside ``protected``
    (the folder of every release). The ``hf`` profile writes parquet shards and a dataset card
    (its licence ``license``, required there) instead of links."""
    if profile_name not in PROFILE_NAMES:
        raise ReleaseError(f"unknown export profile {profile_name!r}: use one of {', '.join(PROFILE_NAMES)}.")
    root, out = Path(root).resolve(), Path(out).absolute()
    doc = read_manifest(root)
    _check_export(root, out, doc, protected)
    if profile_name == HF_PROFILE:
        return _export_hf(root, out, doc, license)
    profile = PROFILES[profile_name]
    planned, names, ids = _plan_files(root, profile, out, doc)
    profile.check_paths(out, [dest for source, _, dest in planned if source == "A"])
    result = ExportResult(
        profile.name, str(out), len(planned), {s: len(v) for s, v in sorted(names.items())},
        dict(profile.split_map), profile.label_rule, profile.honour_ignore, profile.note, ids,
    )  # fmt: skip
    with publish_folder(out) as work:
        _write_files(planned, out, work, copy)
        for rel, lines in profile.lists(names).items():
            (work / rel).parent.mkdir(parents=True, exist_ok=True)
            (work / rel).write_text("".join(f"{line}\n" for line in lines))
        record = result.to_dict() | {
            "release": {"name": doc.name, "version": doc.version, "root": str(root)},
            "tool": profile.tool,
            "links": "copies" if copy else "relative symlinks into the release",
        }
        (work / EXPORT_RECORD).write_text(json.dumps(record, indent=1) + "\n")
    return result
