"""The ``siteline`` command line. Every command has ``--help``; list/show commands take ``--json``."""

from __future__ import annotations

import errno
import os
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import typer
from rich.text import Text

from siteline import __version__
from siteline.cli import bench, db, demo, ingest, labels, previews, release, render, site, synth, watch
from siteline.cli.common import err_console, plain
from siteline.errors import SitelineError, WorkerError


def _click_errors() -> tuple[type[Exception], ...]:
    """The ClickException classes the app may raise: recent typer vendors click as ``typer._click``."""
    import importlib

    found: list[type[Exception]] = []
    for module in ("typer._click.exceptions", "click.exceptions"):
        try:
            found.append(importlib.import_module(module).ClickException)
        except (ImportError, AttributeError):
            continue
    return tuple(found)


_CLICK_ERRORS = _click_errors()

app = typer.Typer(
    name="siteline",
    help="Drone surveys of construction sites turned into change-detection datasets.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)
app.command("init")(db.init)
app.command("demo")(demo.demo)
app.add_typer(db.app, name="db")
app.add_typer(site.app, name="site")
app.command("render")(render.render)
app.add_typer(render.views_app, name="views")
app.add_typer(synth.app, name="synth")
app.command("ingest")(ingest.ingest)
app.add_typer(ingest.mission_app, name="mission")
app.add_typer(ingest.scene_app, name="scene")
app.add_typer(ingest.photo_app, name="photo")
app.add_typer(labels.app, name="labels")
app.add_typer(release.app, name="release")
app.command("train")(release.train_cmd)
app.command("evaluate")(release.evaluate_cmd)
app.command("watch")(watch.watch)
app.add_typer(previews.app, name="previews")
app.add_typer(bench.app, name="bench")


def _print_version(value: bool) -> None:
    if value:
        typer.echo(__version__)
        raise typer.Exit()


def show_logs(verbosity: int) -> None:
    """Show the library's log lines (``logging`` under ``siteline``) on stderr: warnings always (a
    build's differing class schemes, a radius above the ceiling), -v what each stage read, decided
    and wrote (INFO), -vv more (DEBUG)."""
    import logging

    handler = logging.StreamHandler(sys.stderr)
    logger = logging.getLogger("siteline")
    if verbosity <= 0:
        handler.setFormatter(logging.Formatter("warning: %(message)s"))
        logger.handlers = [handler]
        logger.setLevel(logging.WARNING)
        return
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s", "%H:%M:%S"))
    logger.handlers = [handler]
    logger.setLevel(logging.INFO if verbosity == 1 else logging.DEBUG)


@app.callback()
def _root(
    version: bool = typer.Option(
        False, "--version", help="Print the version and exit.", callback=_print_version, is_eager=True
    ),
    verbose: int = typer.Option(
        0, "--verbose", "-v", count=True, help="Show what each stage reads, decides and writes (-vv: more)."
    ),
) -> None:
    """Drone surveys of construction sites turned into change-detection datasets."""
    show_logs(verbose)


# errnos of a destination the user may not write: permission denied, not permitted, read-only file system
_NOT_WRITABLE = (errno.EACCES, errno.EPERM, errno.EROFS)


def _exit_on_sigterm() -> Callable[[], None]:
    """SIGTERM (``kill``, a service manager's stop, a cancelled flow run) ends this process as Ctrl-C
    does: by an exception, so every ``finally`` removes what the command was writing. Forked worker
    processes inherit the handler; in them it keeps the default (die at once: their parent cleans up)."""
    import signal

    owner = os.getpid()

    def terminated(signum: int, _frame: object) -> None:
        if os.getpid() != owner:
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
            return
        raise SystemExit(128 + signum)

    if threading.current_thread() is not threading.main_thread():  # handlers are set in the main thread only
        return lambda: None
    before = signal.signal(signal.SIGTERM, terminated)

    def restore() -> None:
        signal.signal(signal.SIGTERM, before)

    return restore


def main(argv: list[str] | None = None) -> int:
    """Entry point: run the CLI and return its exit status.

    0 success; 1 a command that ran but reports a failure (``release verify`` on a tampered release,
    ``release score`` with missing predictions); 2 a bad request (siteline errors, usage errors).
    With ``standalone_mode=False`` click *returns* the code of a ``typer.Exit`` instead of raising it,
    so the return value is passed on, never dropped.
    """
    restore = _exit_on_sigterm()
    try:
        return _run(argv)
    finally:
        restore()  # main() called in a process that goes on (a test, a notebook) leaves its handler as it was


def _run(argv: list[str] | None) -> int:
    try:
        rc = app(args=argv, standalone_mode=False)
    except SitelineError as exc:
        from siteline.stores.diskspace import disk_full, full_disk_message

        if disk_full(exc):  # a store error on a full disk: one message and status for every full disk
            err_console.print(
                Text.assemble(("error:", "bold red"), " ", full_disk_message(exc, _home())), soft_wrap=True
            )
            return 1
        err_console.print(Text.assemble(("error:", "bold red"), " ", plain(str(exc))), soft_wrap=True)
        return 1 if isinstance(exc, WorkerError) else 2  # a dead worker: the command ran and failed
    except typer.Exit as exc:
        return exc.exit_code
    except typer.Abort:
        err_console.print("aborted")
        return 1
    except _CLICK_ERRORS as exc:  # usage errors: unknown option or command, bad value (status 2)
        usage: Any = exc
        usage.show()
        return int(usage.exit_code)
    except Exception as exc:
        from siteline.catalog.engine import catalog_busy, catalog_busy_message
        from siteline.stores.diskspace import disk_full, full_disk_message

        if isinstance(exc, OSError) and exc.errno in _NOT_WRITABLE and not disk_full(exc):
            # an operator's mistake (a read-only or foreign destination), told in one line
            where = f" {exc.filename}" if exc.filename else ""
            err_console.print(
                Text.assemble(
                    ("error:", "bold red"),
                    " ",
                    f"cannot write{where}: {exc.strerror}; choose a folder you can write to.",
                ),
                soft_wrap=True,
            )
            return 2
        if catalog_busy(exc):
            err_console.print(
                Text.assemble(("error:", "bold red"), " ", catalog_busy_message()), soft_wrap=True
            )
            return 1
        if not disk_full(exc):
            raise
        err_console.print(
            Text.assemble(("error:", "bold red"), " ", full_disk_message(exc, _home())), soft_wrap=True
        )
        return 1  # the command ran and failed for want of space
    return rc if isinstance(rc, int) else 0


def _home() -> Path:
    """SITELINE_HOME as the settings resolve it (its default when they cannot be read)."""
    from siteline.config import load_settings

    try:
        return Path(load_settings().home)
    except Exception:
        return Path(os.environ.get("SITELINE_HOME", "."))


if __name__ == "__main__":
    sys.exit(main())
