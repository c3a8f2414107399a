"""Noticing completed mission uploads in a folder (no orchestration here: the caller emits events).

An upload is a sub-folder of the watched folder. It is complete when it holds the marker file
(default ``.upload-complete``) or when its file list and sizes have not changed for ``stable_s``
seconds. Each completed upload is reported once; what was reported is remembered in
``<watched>/.siteline-watch.json`` so a restarted watcher does not report it again.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

from siteline.stores import write_file

STATE_FILE = ".siteline-watch.json"
MARKER = ".upload-complete"


def _snapshot(folder: Path) -> tuple[tuple[str, int], ...]:
    out = []
    for dirpath, _, files in os.walk(folder):
        for f in files:
            p = Path(dirpath) / f
            try:
                out.append((str(p.relative_to(folder)), p.stat().st_size))
            except OSError:  # a file vanished or is being replaced mid-upload
                continue
    return tuple(sorted(out))


@dataclass
class UploadWatcher:
    """Polls ``root`` for completed uploads."""

    root: Path
    stable_s: float = 30.0
    marker: str = MARKER
    _seen: dict[str, tuple[tuple, float]] = field(default_factory=dict)
    _reported: set[str] = field(default_factory=set)

    def __post_init__(self) -> None:
        self.root = Path(self.root)
        self.root.mkdir(parents=True, exist_ok=True)
        state = self.root / STATE_FILE
        if state.exists():
            self._reported = set(json.loads(state.read_text()).get("reported", []))

    def _save(self) -> None:
        data = json.dumps({"reported": sorted(self._reported)}).encode()
        write_file(self.root / STATE_FILE, lambda fh: fh.write(data))

    def poll(self, now: float | None = None) -> list[Path]:
        """Uploads that became complete since the last poll (each reported once)."""
        now = time.monotonic() if now is None else now
        done = []
        for folder in sorted(p for p in self.root.iterdir() if p.is_dir() and not p.name.startswith(".")):
            if folder.name in self._reported:
                continue
            snap = _snapshot(folder)
            if not snap:
                continue
            if (folder / self.marker).exists():
                done.append(folder)
                continue
            prev = self._seen.get(folder.name)
            if prev is None or prev[0] != snap:
                self._seen[folder.name] = (snap, now)
            elif now - prev[1] >= self.stable_s:
                done.append(folder)
        for folder in done:
            self._reported.add(folder.name)
            self._seen.pop(folder.name, None)
        if done:
            self._save()
        return done
