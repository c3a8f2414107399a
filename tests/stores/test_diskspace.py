"""A full disk told in one line, without mounting anything: which errors count as a full disk, what
the line says, and the CLI's exit status and output when a command hits one (the tmpfs test in
tests/stores/test_full_disk.py fills a real disk where mounting is allowed)."""

from __future__ import annotations

import errno
import sqlite3

import psycopg
import pytest
import sqlalchemy as sa

from siteline.catalog.engine import catalog_busy
from siteline.stores.diskspace import disk_full, full_disk_message


def _raised_from(cause: BaseException) -> RuntimeError:
    try:
        try:
            raise cause
        except BaseException as exc:
            raise RuntimeError("writing tiles failed") from exc
    except RuntimeError as outer:
        return outer


def test_full_disks_are_told_apart_from_other_errors(tmp_path) -> None:
    full = OSError(errno.ENOSPC, "No space left on device", str(tmp_path / "tile.bin"))
    assert disk_full(full) and disk_full(OSError(errno.EDQUOT, "Disk quota exceeded"))
    assert disk_full(_raised_from(full))  # found through the chain
    assert disk_full(sa.exc.OperationalError("COMMIT", {}, _sqlite_error("database or disk is full", 13)))
    pg = psycopg.errors.DiskFull("could not extend file")
    assert pg.sqlstate == "53100" and disk_full(sa.exc.OperationalError("INSERT", {}, pg))
    assert not disk_full(OSError(errno.EACCES, "Permission denied")) and not disk_full(KeyError("x"))
    line = full_disk_message(_raised_from(full), tmp_path / "home" / "not-yet")
    assert f"writing {tmp_path / 'tile.bin'}" in line and "MB free of" in line and "\n" not in line
    # the free space of the disk that filled (the file's), not the home's
    assert f"the file system holding {tmp_path} has" in line
    unknown = full_disk_message(
        OSError(errno.ENOSPC, "No space left on device"), tmp_path / "home" / "not-yet"
    )
    assert (
        f"the file system holding {tmp_path} has" in unknown
    )  # the home's, from its nearest existing folder


def test_a_full_disk_is_told_by_errno_never_by_a_file_name() -> None:
    # a missing file whose name says "No space left on device": a missing file, not a full disk
    missing = FileNotFoundError(
        errno.ENOENT, "No such file or directory", "/data/No space left on device/a.laz"
    )
    assert not disk_full(missing) and not disk_full(_raised_from(missing))
    assert not disk_full(RuntimeError("scene 'no space left on device' not found"))
    assert not disk_full(KeyError("database or disk is full"))  # only a database's own code counts
    assert disk_full(OSError("15321 requested and 8763 written"))  # numpy's short write, no errno
    # a path or a database named with those words is what it is: a missing mission, a missing database
    assert not disk_full(ValueError("15321 requested and 8763 written"))
    assert not disk_full(OSError("mission /data/15 requested and 3 written/ not found"))
    missing_db = psycopg.errors.InvalidCatalogName('database "could not extend file" does not exist')
    assert not disk_full(sa.exc.OperationalError("connect", {}, missing_db))
    named = _sqlite_error("unable to open database file /data/database or disk is full/catalog.sqlite", 14)
    assert not disk_full(sa.exc.OperationalError("connect", {}, named))
    assert not disk_full(
        sa.exc.OperationalError("COMMIT", {}, sqlite3.OperationalError("database or disk is full"))
    )


def test_a_catalog_held_by_another_writer_is_told_by_sqlite_code() -> None:
    locked = sa.exc.OperationalError("INSERT", {}, _sqlite_error("database is locked", 5))
    assert catalog_busy(locked) and not disk_full(locked)
    assert catalog_busy(_raised_from(_sqlite_error("database is locked", 517)))  # SQLITE_BUSY_SNAPSHOT
    assert not catalog_busy(sa.exc.OperationalError("x", {}, sqlite3.OperationalError("database is locked")))


def _sqlite_error(message: str, code: int) -> sqlite3.OperationalError:
    """A sqlite3 error as SQLite raises it: with its result code."""
    exc = sqlite3.OperationalError(message)
    exc.sqlite_errorcode = code
    return exc


def test_the_cli_ends_a_full_disk_with_one_line_and_exit_1(tmp_path, monkeypatch, capsys) -> None:
    from siteline import cli
    from siteline.cli import site as site_cli

    monkeypatch.setenv("SITELINE_HOME", str(tmp_path / "home"))
    monkeypatch.delenv("SITELINE_DATABASE_URL", raising=False)

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(site_cli, "list_sites", full)
    assert cli.main(["init"]) == 0
    capsys.readouterr()
    assert cli.main(["site", "list"]) == 1
    err = capsys.readouterr().err
    assert "error: the disk is full" in err and "Traceback" not in err
    monkeypatch.setattr(site_cli, "list_sites", lambda *a, **k: (_ for _ in ()).throw(KeyError("bug")))
    with pytest.raises(KeyError):  # any other error is not dressed up as a full disk
        cli.main(["site", "list"])
