"""The read-only HTTP route for previews: ``/previews/...`` and ``/releases/...`` under SITELINE_HOME
(published releases only: drafts and temporary folders are hidden), GET and HEAD only, nothing
outside those two folders whatever the path or a symlink says."""

from __future__ import annotations

import html
import http.server
import io
import logging
import os
from functools import partial
from pathlib import Path
from typing import Any
from urllib.parse import quote, unquote, urlsplit

from siteline.stores import layout

log = logging.getLogger(__name__)
SERVED = ("previews", "releases")


def _allowed(home: Path, url_path: str) -> Path | None:
    """The file or folder ``url_path`` names, when it lies in a served folder and no part of it is
    hidden; else None."""
    parts = [p for p in unquote(urlsplit(url_path).path).split("/") if p]
    if not parts or parts[0] not in SERVED or any(p.startswith(".") or p in ("..",) for p in parts):
        return None
    target = home.joinpath(*parts)
    roots = [os.path.realpath(home / name) for name in SERVED]
    real = os.path.realpath(target)
    if not any(real == r or real.startswith(r + os.sep) for r in roots):
        return None
    return target


class PreviewHandler(http.server.SimpleHTTPRequestHandler):
    """GET and HEAD of files under the served folders; every other method is refused (501)."""

    home: Path

    def __init__(self, *args: Any, home: Path, **kwargs: Any) -> None:
        self.home = home
        super().__init__(*args, directory=str(home), **kwargs)

    def send_head(self) -> io.BufferedIOBase | io.BytesIO | None:  # type: ignore[override]
        if self.path in ("/", ""):
            body = b'<html><body><a href="/releases/">releases</a> <a href="/previews/">previews</a></body></html>'
            self.send_response(200)
            self.send_header("Content-Type", "text/html; charset=utf-8")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            return io.BytesIO(body)
        if _allowed(self.home, self.path) is None:
            self.send_error(404, "not a preview or a published release file")
            return None
        return super().send_head()  # type: ignore[return-value]

    def list_directory(self, path: str | os.PathLike[str]) -> io.BytesIO | None:
        """The folder's entries as links, hidden ones (drafts, temporary folders) left out."""
        try:
            names = sorted(n for n in os.listdir(path) if not n.startswith("."))
        except OSError:
            self.send_error(404, "no such folder")
            return None
        base = self.path if self.path.endswith("/") else self.path + "/"
        links = "".join(
            f'<li><a href="{html.escape(base + quote(n + ("/" if os.path.isdir(os.path.join(path, n)) else "")))}">'
            f"{html.escape(n)}</a></li>"
            for n in names
        )
        body = f"<html><body><h1>{html.escape(unquote(base))}</h1><ul>{links}</ul></body></html>".encode()
        self.send_response(200)
        self.send_header("Content-Type", "text/html; charset=utf-8")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        return io.BytesIO(body)

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 (the base class's name)
        log.debug("%s " + format, self.address_string(), *args)


def make_server(home: Path, host: str, port: int) -> http.server.ThreadingHTTPServer:
    """A server of ``home``'s previews and published releases on ``host``:``port`` (not started)."""
    layout.previews(home).mkdir(parents=True, exist_ok=True)
    layout.releases(home).mkdir(parents=True, exist_ok=True)
    return http.server.ThreadingHTTPServer((host, port), partial(PreviewHandler, home=Path(home)))
