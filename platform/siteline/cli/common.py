"""What every CLI command shares: settings, the catalog, JSON or table output, errors."""

from __future__ import annotations

import json
import re
import sys
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from datetime import datetime
from pathlib import Path
from typing import Any

import typer
from rich.console import Console
from rich.table import Table

from siteline.catalog import Catalog, open_catalog
from siteline.config import Settings, load_settings
from siteline.progress import Progress

_CONTROL = re.compile(r"[\x00-\x08\x0b-\x1f\x7f-\x9f]")


def plain(value: object) -> str:
    """``value`` as text safe to print: control characters (terminal escape sequences from a note or
    a file name) shown as ``\\x1b`` instead of acted on."""
    return _CONTROL.sub(lambda m: repr(m.group())[1:-1], str(value))


class TextConsole(Console):
    """A rich console that prints strings as plain text: text from users and files (paths, notes,
    errors) is never read as markup, and its control characters are escaped."""

    def __init__(self, **kw: Any) -> None:
        super().__init__(markup=False, highlight=False, emoji=False, soft_wrap=True, **kw)

    def print(self, *objects: Any, **kw: Any) -> None:
        super().print(*(plain(o) if isinstance(o, str) else o for o in objects), **kw)


console = TextConsole()
err_console = TextConsole(stderr=True)

JsonOption = typer.Option(False, "--json", help="Print machine-readable JSON instead of a table.")


def settings() -> Settings:
    return load_settings()


@contextmanager
def catalog(check: bool = True) -> Iterator[Catalog]:
    """The configured catalog, disposed of at the end of the block."""
    cat = open_catalog(settings(), check=check)
    try:
        yield cat
    finally:
        cat.dispose()


def _default(obj: Any) -> Any:
    if isinstance(obj, datetime):
        return obj.isoformat()
    if isinstance(obj, Path):
        return str(obj)
    if hasattr(obj, "tolist"):
        return obj.tolist()
    raise TypeError(f"cannot serialise {type(obj).__name__}")


def print_json(data: Any) -> None:
    """JSON on stdout, nothing else (so ``--json`` output can be piped)."""
    sys.stdout.write(json.dumps(data, indent=2, default=_default, sort_keys=False) + "\n")


def print_table(title: str, columns: Sequence[str], rows: Sequence[Sequence[Any]]) -> None:
    table = Table(title=title)
    for col in columns:
        table.add_column(col)
    for row in rows:
        table.add_row(*("" if v is None else plain(v) for v in row))
    console.print(table)


def print_record(title: str, record: Mapping[str, object]) -> None:
    table = Table(title=title, show_header=False)
    table.add_column("field", style="bold")
    table.add_column("value")
    for key, value in record.items():
        if isinstance(value, dict | list):
            value = json.dumps(value, default=_default)
            if len(value) > 200:
                value = value[:197] + "..."
        table.add_row(plain(key), "" if value is None else plain(value))
    console.print(table)


def emit(as_json: bool, data: Any, human: Callable[[], None]) -> None:
    if as_json:
        print_json(data)
    else:
        human()


@contextmanager
def progress_bars(hidden: bool, amounts: str = "") -> Iterator[Progress]:
    """Rich progress bars on the console while the block runs (none when ``hidden``, e.g. ``--json``),
    as a :class:`siteline.progress.Progress`; ``amounts``: ``bytes`` or ``count`` shows the amount
    done beside each bar (and the time left)."""
    from rich import progress as rp

    columns: list[Any] = [rp.TextColumn("{task.description}"), rp.BarColumn()]
    if not amounts:
        columns = list(rp.Progress.get_default_columns())
    elif amounts == "bytes":
        columns += [rp.DownloadColumn(binary_units=True), rp.TimeRemainingColumn()]
    elif amounts == "count":
        columns += [rp.TextColumn("{task.completed:,}"), rp.TimeRemainingColumn()]
    with rp.Progress(*columns, console=console, transient=True, disable=hidden) as bar:
        yield bar_progress(bar)


def bar_progress(bar: Any) -> Progress:
    """A :class:`siteline.progress.Progress` drawing one rich bar per task on ``bar``."""
    tasks: dict[str, int] = {}

    def report(task: str, amount: int, total: int | None) -> None:
        if task not in tasks:
            tasks[task] = bar.add_task(task, total=total)
        elif total is not None:
            bar.update(tasks[task], total=total)
        if amount:
            bar.advance(tasks[task], amount)

    return report
