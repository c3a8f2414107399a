"""Who owns a temporary name: every partial folder or temporary file siteline makes carries an owner
tag (host, process id, random token), so a writer clears only leftovers that are provably stale (made
on this host by a process that is gone), never another live writer's work."""

from __future__ import annotations

import fnmatch
import os
import re
import shutil
import socket
import uuid
from pathlib import Path

_TAG = re.compile(r"(?P<host>[A-Za-z0-9_]+)\+(?P<pid>\d+)\+(?P<token>[0-9a-f]{8,})")


def _host() -> str:
    return re.sub(r"[^A-Za-z0-9_]", "_", socket.gethostname()) or "host"


def owner_tag() -> str:
    """``<host>+<pid>+<token>``: this process's mark on a temporary name."""
    return f"{_host()}+{os.getpid()}+{uuid.uuid4().hex[:12]}"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's live process
        return True
    return True


def is_stale(name: str) -> bool:
    """Whether the temporary ``name`` was made on this host by a process that no longer runs. A name
    without an owner tag, or made on another host, is never provably stale."""
    m = _TAG.search(name)
    if m is None or m.group("host") != _host():
        return False
    pid = int(m.group("pid"))
    return pid != os.getpid() and not _alive(pid)


def sweep_stale(folder: Path, pattern: str) -> list[Path]:
    """Remove the entries of ``folder`` whose names match the glob ``pattern`` and are provably stale
    (:func:`is_stale`); return what was removed."""
    removed: list[Path] = []
    if not folder.is_dir():
        return removed
    for entry in folder.iterdir():
        if fnmatch.fnmatchcase(entry.name, pattern) and is_stale(entry.name):
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry, ignore_errors=True)
            else:
                entry.unlink(missing_ok=True)
            removed.append(entry)
    return removed
