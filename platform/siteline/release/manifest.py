"""Release manifests: file checksums, verification, and the datasheet's figures."""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Sequence
from pathlib import Path
from typing import cast

from siteline.errors import ReleaseError
from siteline.hashing import sha256_file
from siteline.records.release import FileEntry, Manifest, ManifestDoc
from siteline.schema import JSON, validate

MANIFEST = "manifest.json"
METRIC_DEFINITION: dict[str, JSON] = {
    "name": "siteline-cd-metrics/1",
    "confusion": "one 2x2 confusion matrix accumulated over every pixel of the split; label 255 excluded",
    "reported": [
        "iou_unchanged",
        "iou_changed",
        "miou (mean of the IoUs of the classes present in truth or prediction; a class absent from both has "
        "no IoU, as in torchmetrics)",
        "precision/recall/f1 of changed",
        "overall accuracy",
        "cohen kappa",
    ],
    "per_image": "scores_per_image: the paper's (Pylon's) convention: per-image IoU per class, NaN for a class "
    "absent from the image's truth and prediction, nanmean over images, mIoU the mean of the two classes",
    "note": "the two conventions differ by a few mIoU points; say which one a number is",
}


def file_entries(root: Path) -> list[FileEntry]:
    """Every file under ``root`` except the manifest: POSIX path, size, sha256, sorted by path."""
    out: list[FileEntry] = []
    for p in sorted(root.rglob("*")):
        if p.is_file() and p.name != MANIFEST:
            out.append(
                {"path": p.relative_to(root).as_posix(), "size": p.stat().st_size, "sha256": sha256_file(p)}
            )
    return out


def write_manifest(root: Path, doc: ManifestDoc) -> str:
    """Validate and write ``manifest.json``; return its sha256."""
    validate(doc, "release.schema.json", f"manifest of {root}")
    data = (json.dumps(doc, indent=1, sort_keys=False) + "\n").encode()
    (root / MANIFEST).write_bytes(data)
    return hashlib.sha256(data).hexdigest()


def read_manifest(root: Path) -> Manifest:
    """The manifest of the release at ``root``, as a record; :class:`ReleaseError` names the file
    when it is missing, not JSON, or not a release manifest."""
    path = Path(root) / MANIFEST
    doc = _read_document(root)
    try:
        return Manifest.from_dict(doc)
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise ReleaseError(
            f"{path} is not a siteline release manifest ({type(exc).__name__}: {exc})."
        ) from exc


def _read_document(root: Path) -> ManifestDoc:
    """The manifest of ``root`` as the JSON document it is (verification reads it so: a tampered one
    is reported, not refused)."""
    path = Path(root) / MANIFEST
    if not path.is_file():
        raise ReleaseError(f"{root} holds no {MANIFEST}: not a siteline release (or not built yet).")
    try:
        doc = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ReleaseError(f"{path} is not valid JSON: {exc}") from exc
    if not isinstance(doc, dict):
        raise ReleaseError(f"{path} holds a JSON {type(doc).__name__}, not a release manifest.")
    return cast(ManifestDoc, doc)  # read as the format states it; verification reports what is not


SAFE_ITEM_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,200}")


def safe_relative(path: str) -> bool:
    """Whether a manifest path stays inside the release: relative, POSIX, no '..' and no empty part."""
    parts = path.split("/")
    return (
        bool(path)
        and not path.startswith("/")
        and "\\" not in path
        and all(p not in ("", ".", "..") for p in parts)
    )


def _absolute_paths(node: object, where: str) -> list[tuple[str, str]]:
    """Every string under ``node`` that is an absolute file-system path, with where it lies."""
    if isinstance(node, dict):
        return [hit for k, v in node.items() for hit in _absolute_paths(v, f"{where}.{k}")]
    if isinstance(node, list):
        return [hit for i, v in enumerate(node) for hit in _absolute_paths(v, f"{where}[{i}]")]
    if isinstance(node, str) and (node.startswith("/") or re.match(r"^[A-Za-z]:[\\/]", node)):
        return [(where, node)]
    return []


def verify_files(
    root: Path, manifest_sha256: str | None = None, recorded_files: Sequence[str] = ()
) -> list[str]:
    """Problems found by recomputing every checksum of the manifest, one line each: a file missing,
    resized, changed, replaced by a symlink or not listed; a listed path or item id that leaves the
    release; given the catalog's ``manifest_sha256``, a manifest that is not the one recorded
    (edited fields, a forged file whose entry was updated to match) or that is missing; and each of
    ``recorded_files`` (the item images the catalog recorded) that is missing or left unlisted, which
    is checked even when the manifest is gone."""
    root = Path(root)
    problems = []
    present = (root / MANIFEST).is_file()
    gone = [rel for rel in recorded_files if not (root / rel).is_file()]
    if manifest_sha256 is not None and not present:
        problems.append(
            f"{MANIFEST}: missing (the catalog recorded sha256 {manifest_sha256[:12]}...): tampered with"
        )
    if not present:
        return problems + [f"{rel}: missing (recorded by the catalog)" for rel in gone]
    if manifest_sha256 is not None:
        actual = (
            hashlib.sha256((root / MANIFEST).read_bytes()).hexdigest()
            if (root / MANIFEST).is_file()
            else None
        )
        if actual != manifest_sha256:
            problems.append(
                f"{MANIFEST}: sha256 differs from the catalog's record ({manifest_sha256[:12]}...)"
            )
    doc = _read_document(root)
    problems += [
        f"{MANIFEST}: {where} records the absolute path {value!r}; a release records paths relative to its "
        "home or store (one built by a version before that: build it again)"
        for where, value in _absolute_paths(doc.get("lineage", {}), "lineage")
    ]
    listed = set()
    named = {f["path"] for f in doc["files"]}
    problems += [
        f"{rel}: recorded by the catalog but not in the manifest"
        for rel in recorded_files
        if rel not in named
    ]
    for f in doc["files"]:
        rel = f["path"]
        listed.add(rel)
        if not safe_relative(rel):
            problems.append(f"{rel}: a manifest path that leaves the release")
            continue
        p = root / rel
        if p.is_symlink():
            problems.append(f"{rel}: a symlink, not the file the manifest lists")
        elif not p.is_file():
            problems.append(f"{rel}: missing")
        elif p.stat().st_size != f["size"]:
            problems.append(f"{rel}: size {p.stat().st_size} != {f['size']}")
        elif sha256_file(p) != f["sha256"]:
            problems.append(f"{rel}: sha256 differs from the manifest")
    for item in doc.get("items", []):
        if not SAFE_ITEM_ID.fullmatch(str(item.get("id", ""))):
            problems.append(f"item id {item.get('id')!r}: not a file name (letters, digits, '_', '.', '-')")
    for p in sorted(root.rglob("*")):
        if (
            (p.is_file() or p.is_symlink())
            and p.name != MANIFEST
            and p.relative_to(root).as_posix() not in listed
        ):
            problems.append(f"{p.relative_to(root).as_posix()}: not in the manifest")
    return problems
