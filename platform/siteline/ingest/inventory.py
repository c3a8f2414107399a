"""Inventory of a mission folder: every file's relative path, size, sha256 and kind, and the mission
manifest hash that identifies the mission (DESIGN.md §1, §9.1)."""

from __future__ import annotations

import errno
import hashlib
import json
import os
import stat
from collections.abc import Callable, Sequence
from pathlib import Path, PurePosixPath

from siteline.errors import MissionError
from siteline.hashing import sha256_file
from siteline.ingest.watch import MARKER, STATE_FILE
from siteline.progress import no_step
from siteline.records.enums import FileKind
from siteline.records.mission import FileEntry, MissionManifest

# files an upload leaves in a mission folder that are not the mission's: the upload-complete marker and
# the watcher's state; the same mission with or without them is the same mission
NOT_MISSION_CONTENT = frozenset({MARKER, STATE_FILE})
RAW_SUFFIXES = {
    ".ldr",
    ".clc",
    ".cli",
    ".imu",
    ".rtk",
    ".rts",
    ".rtl",
    ".rtb",
    ".sig",
    ".ldrt",
    ".rpt",
    ".rpos",
    ".cmi",
}
COLMAP_FILES = {
    "cameras.bin",
    "images.bin",
    "points3d.bin",
    "rigs.bin",
    "frames.bin",
    "cameras.txt",
    "images.txt",
    "points3d.txt",
    "rigs.txt",
    "frames.txt",
}


def file_kind(rel: PurePosixPath) -> FileKind:
    name = rel.name.lower()
    suffix = rel.suffix.lower()
    if suffix in (".las", ".laz"):
        return "las"
    if suffix in (".jpg", ".jpeg"):
        return "photo"
    if name in COLMAP_FILES:
        return "colmap"
    if name.endswith("_sbet.out") or suffix == ".out":
        return "trajectory"
    if suffix in RAW_SUFFIXES:
        return "raw"
    return "other"


def check_relative(rel: str, root: Path) -> PurePosixPath:
    """A safe relative POSIX path inside the mission folder, or :class:`MissionError`."""
    p = PurePosixPath(rel)
    if p.is_absolute() or rel.startswith(("/", "\\")):
        raise MissionError(f"mission {root}: file name {rel!r} is an absolute path.")
    if any(part == ".." for part in p.parts) or "\\" in rel or "\0" in rel:
        raise MissionError(f"mission {root}: file name {rel!r} leaves the mission folder ('..').")
    return p


def _resolve(full: Path, rel: str, root: Path) -> Path:
    """Where the symlink ``full`` leads; :class:`MissionError` for a loop or a dangling link."""
    try:
        return full.resolve(strict=True)
    except RuntimeError as exc:  # "Symlink loop" (Python 3.11)
        raise MissionError(f"mission {root}: {rel} is a symlink loop ({exc}): remove it.") from exc
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise MissionError(f"mission {root}: {rel} is a symlink loop: remove it.") from exc
        raise MissionError(f"mission {root}: {rel} is a broken symlink.") from exc


def _check_dir_link(full: Path, root: Path, root_real: Path) -> None:
    if full.is_symlink():
        rel = full.relative_to(root).as_posix()
        if not _resolve(full, rel, root).is_relative_to(root_real):
            raise MissionError(
                f"mission {root}: {rel} is a symlink to {os.readlink(full)}, outside the mission folder."
            )


def _check_file(full: Path, rel: PurePosixPath, root: Path, root_real: Path) -> None:
    """A regular file inside the mission, or :class:`MissionError` naming what it is instead."""
    if full.is_symlink():
        link = os.readlink(full)
        target = _resolve(full, str(rel), root)
        where = "the absolute path " if os.path.isabs(link) else ""
        if not target.is_relative_to(root_real):
            raise MissionError(
                f"mission {root}: {rel} is a symlink to {where}{link}, outside the mission folder."
            )
    mode = full.stat().st_mode
    if not stat.S_ISREG(mode):
        kind = (
            "FIFO" if stat.S_ISFIFO(mode) else "socket" if stat.S_ISSOCK(mode)
            else "device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else "special file"
        )  # fmt: skip
        raise MissionError(f"mission {root}: {rel} is a {kind}, not a file: remove it (nothing was read).")


def _walk(root: Path) -> list[tuple[PurePosixPath, Path]]:
    out = []
    root_real = root.resolve()
    for dirpath, dirnames, filenames in os.walk(root, followlinks=False):
        dirnames.sort()
        here = Path(dirpath)
        for d in list(dirnames):
            _check_dir_link(here / d, root, root_real)
        for name in sorted(filenames):
            if here == root and name in NOT_MISSION_CONTENT:
                continue
            full = here / name
            rel = check_relative(full.relative_to(root).as_posix(), root)
            _check_file(full, rel, root, root_real)
            out.append((rel, full))
    return out


def inventory(
    root: Path, progress: Callable[[int], None] | None = None, total: Callable[[int], None] | None = None
) -> list[FileEntry]:
    """Every regular file under ``root`` with its hash, sorted by path. ``total`` receives the byte
    count before hashing starts, ``progress`` the bytes hashed as they go."""
    root = Path(root)
    if not root.is_dir():
        raise MissionError(
            f"mission folder {root} does not exist or is not a folder (nor a .las or .laz file)."
        )
    files = _walk(root)
    if not files:
        raise MissionError(f"mission folder {root} is empty.")
    sizes = [full.stat().st_size for _, full in files]
    if total:
        total(sum(sizes))
    return [
        FileEntry(rel.as_posix(), size, sha256_file(full, progress), file_kind(rel))
        for (rel, full), size in zip(files, sizes, strict=True)
    ]


def manifest_sha256(entries: Sequence[FileEntry]) -> str:
    """sha256 of the canonical manifest: sorted (path, size, sha256) triples as compact JSON."""
    doc = [[e.path, e.size_bytes, e.sha256] for e in sorted(entries, key=lambda e: e.path)]
    return hashlib.sha256(json.dumps(doc, separators=(",", ":")).encode()).hexdigest()


def mission_manifest(root: Path, progress: Callable[..., None] = no_step) -> MissionManifest:
    """The inventory of the mission folder ``root`` and its manifest hash; ``root`` may also be one
    LAS/LAZ file, a mission of that file alone (its folder is the mission's root, nothing else in it
    is read). ``progress(amount, total)`` receives the byte count before hashing starts and the bytes
    hashed as they go."""
    root = Path(root).resolve() if Path(root).exists() else Path(root)
    if root.is_file() and file_kind(PurePosixPath(root.name)) == "las":
        _check_file(root, PurePosixPath(root.name), root.parent, root.parent.resolve())
        size = root.stat().st_size
        progress(0, size)
        entries = [FileEntry(root.name, size, sha256_file(root, progress), "las")]
        return MissionManifest(root.parent, tuple(entries), manifest_sha256(entries))
    entries = inventory(root, progress=progress, total=lambda t: progress(0, t))
    return MissionManifest(root, tuple(entries), manifest_sha256(entries))
