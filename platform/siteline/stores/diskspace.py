"""A full disk, told in one line: which file system, how much is free, what to do."""

from __future__ import annotations

import errno
import re
import shutil
from pathlib import Path

_FULL_ERRNOS = {errno.ENOSPC, errno.EDQUOT}
# what SQLite and PostgreSQL say (through SQLAlchemy) when their disk is full
_FULL_TEXTS = ("database or disk is full", "no space left on device", "could not extend file")
# a short write with no errno (numpy's tofile: "15321 requested and 8763 written"): the disk took
# less than it was given, which on a local file system means it is full
_SHORT_WRITE = re.compile(r"\b\d+ requested and \d+ written\b")


# the drivers whose errors carry no errno and say a full disk in words
_DATABASE_MODULES = ("sqlalchemy", "sqlite3", "psycopg", "psycopg2")


def _says_full(exc: BaseException) -> bool:
    """Whether this one exception reports a full disk: by its errno when it has one (never by its
    text, which may hold a file name), by a database driver's words, or by a short write."""
    if isinstance(exc, OSError) and exc.errno is not None:
        return exc.errno in _FULL_ERRNOS
    text = str(exc).lower()
    if type(exc).__module__.split(".")[0] in _DATABASE_MODULES:
        return any(t in text for t in _FULL_TEXTS)
    return isinstance(exc, OSError | ValueError) and bool(_SHORT_WRITE.search(text))


def disk_full(exc: BaseException) -> bool:
    """Whether ``exc`` (or an exception it was raised from) says a disk is full."""
    seen: set[int] = set()
    cur: BaseException | None = exc
    while cur is not None and id(cur) not in seen:
        seen.add(id(cur))
        if _says_full(cur):
            return True
        cur = cur.__cause__ or cur.__context__
    return False


def full_disk_message(exc: BaseException, home: Path) -> str:
    """One line for a command that stopped on a full disk: the file it was writing when known, the
    free space of the file system that holds it (else of ``home``, SITELINE_HOME: catalog, stores,
    scratch), and the fix."""
    cur: BaseException | None = exc
    where, filled = "", Path(home)
    while cur is not None:
        if isinstance(cur, OSError) and cur.filename:
            where, filled = f" writing {cur.filename}", Path(str(cur.filename))
            break
        cur = cur.__cause__ or cur.__context__
    probe = filled  # the file system that filled: the file's when known, else the home's
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    usage = shutil.disk_usage(probe)
    return (
        f"the disk is full{where}: the file system holding {probe} has {usage.free / 1e6:.1f} MB free of "
        f"{usage.total / 1e6:.0f} MB. Free space there (or set SITELINE_HOME or SITELINE_STORE_URL to a "
        "larger disk) and run the command again; what this run was writing has been removed."
    )
