"""Noticing completed mission uploads in a folder (no orchestration here: the caller emits events).

An upload is a sub-folder of the watched folder. It is complete when it holds the marker file
(default ``.upload-complete``) or when its file list, sizes and modification times have not changed
for ``stable_s`` seconds. A completed upload is reported once for its content: the fingerprint of
what was reported is remembered in ``<watched>/.siteline-watch.json`` (so a restarted watcher does
not report it again), and a folder whose content changes afterwards (a failed upload fixed in place:
a file replaced, the marker touched) is reported again once complete. An upload counts as reported
only when the caller confirms it (:meth:`UploadWatcher.confirm`, after its event went out).
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

from siteline.stores import write_file

STATE_FILE = ".siteline-watch.json"
MARKER = ".upload-complete"

Snapshot = tuple[tuple[str, int, int], ...]


def _snapshot(folder: Path) -> Snapshot:
    """(relative path, size, mtime in ns) of every file under ``folder``, sorted."""
    out = []
    for dirpath, _, files in os.walk(folder):
        for f in files:
            p = Path(dirpath) / f
            try:
                st = p.stat()
            except OSError:  # a file vanished or is being replaced mid-upload
                continue
            out.append((str(p.relative_to(folder)), st.st_size, st.st_mtime_ns))
    return tuple(sorted(out))


def fingerprint(snap: Snapshot) -> str:
    """A short hash of an upload's file list, sizes and modification times."""
    return hashlib.sha256(json.dumps(snap).encode()).hexdigest()[:16]


@dataclass
class UploadWatcher:
    """Polls ``root`` for completed uploads."""

    root: Path
    stable_s: float = 30.0
    marker: str = MARKER
    _seen: dict[str, tuple[Snapshot, float]] = field(default_factory=dict)
    _reported: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.root = Path(self.root)
        self.root.mkdir(parents=True, exist_ok=True)
        state = self.root / STATE_FILE
        if state.exists():
            reported = json.loads(state.read_text()).get("reported", {})
            if isinstance(reported, list):  # written before fingerprints: take what is there as reported
                reported = {name: fingerprint(_snapshot(self.root / name)) for name in reported}
            self._reported = dict(reported)

    def _save(self) -> None:
        data = json.dumps({"reported": dict(sorted(self._reported.items()))}).encode()
        write_file(self.root / STATE_FILE, lambda fh: fh.write(data))

    def poll(self, now: float | None = None) -> list[Path]:
        """Uploads complete now whose content was not reported yet (confirm each once announced)."""
        now = time.monotonic() if now is None else now
        done = []
        for folder in sorted(p for p in self.root.iterdir() if p.is_dir() and not p.name.startswith(".")):
            snap = _snapshot(folder)
            if not snap or self._reported.get(folder.name) == fingerprint(snap):
                continue
            prev = self._seen.get(folder.name)
            if prev is None or prev[0] != snap:
                self._seen[folder.name] = (snap, now)
            if (folder / self.marker).exists() or (
                prev is not None and prev[0] == snap and now - prev[1] >= self.stable_s
            ):
                done.append(folder)
        return done

    def confirm(self, folder: Path) -> str:
        """Remember ``folder``'s content as reported; return its fingerprint."""
        fp = fingerprint(self._seen.pop(folder.name, (_snapshot(folder), 0.0))[0])
        self._reported[folder.name] = fp
        self._save()
        return fp

    def pending_fingerprint(self, folder: Path) -> str:
        """The fingerprint of ``folder``'s content as the last poll saw it."""
        return fingerprint(self._seen.get(folder.name, (_snapshot(folder), 0.0))[0])
