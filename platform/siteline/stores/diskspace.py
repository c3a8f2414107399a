"""A full disk, told in one line: which file system, how much is free, what to do. Errors are told
apart by their codes along their chain (:func:`error_chain`, :func:`sqlite_code`), never by words."""

from __future__ import annotations

import errno
import re
import shutil
from collections.abc import Iterator
from pathlib import Path

_FULL_ERRNOS = {errno.ENOSPC, errno.EDQUOT}
# the databases' own codes for a full disk: SQLite's SQLITE_FULL (sqlite3 errors carry it as
# sqlite_errorcode), PostgreSQL's SQLSTATE 53100 disk_full (psycopg errors carry it as sqlstate);
# their messages are never read (a database or file may be named with those words)
_SQLITE_FULL = 13
_POSTGRES_DISK_FULL = "53100"
# a short write with no errno: numpy's tofile raises OSError("15321 requested and 8763 written")
# when the disk took less than it was given, which on a local file system means it is full; the
# whole message must be that (a path holding those words is not one)
_SHORT_WRITE = re.compile(r"\d+ requested and \d+ written")


def error_chain(exc: BaseException) -> Iterator[BaseException]:
    """``exc``, the exceptions it was raised from, and a database error's driver error (``orig``)."""
    seen: set[int] = set()
    todo: list[BaseException] = [exc]
    while todo:
        cur = todo.pop()
        if id(cur) in seen:
            continue
        seen.add(id(cur))
        yield cur
        todo.extend(
            e
            for e in (getattr(cur, "orig", None), cur.__cause__, cur.__context__)
            if isinstance(e, BaseException)
        )


def sqlite_code(exc: BaseException) -> int | None:
    """A sqlite3 error's primary result code (its extended code's low byte), None for others."""
    code = getattr(exc, "sqlite_errorcode", None)
    return code & 0xFF if isinstance(code, int) else None


def _says_full(exc: BaseException) -> bool:
    """Whether this one exception reports a full disk: by its errno when it has one, by a database's
    own error code, or by a short write's whole message; never by words in a longer text, which may
    hold a file's or a database's name."""
    if isinstance(exc, OSError) and exc.errno is not None:
        return exc.errno in _FULL_ERRNOS
    if sqlite_code(exc) == _SQLITE_FULL:
        return True
    if getattr(exc, "sqlstate", None) == _POSTGRES_DISK_FULL:
        return True
    return type(exc) is OSError and bool(_SHORT_WRITE.fullmatch(str(exc).strip()))


def disk_full(exc: BaseException) -> bool:
    """Whether ``exc`` (or an exception it was raised from) says a disk is full."""
    return any(_says_full(e) for e in error_chain(exc))


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
