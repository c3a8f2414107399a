"""The read-only HTTP server of previews and releases: ``/previews/...`` and ``/releases/...`` under
SITELINE_HOME (published releases only: drafts and temporary folders are hidden); the release
browser ``/browse/<name>/<version>/`` (its images under ``files/``) and the 3D pair viewer
``/3d/<name>/<version>/<pair>/`` (its plan ``plan.json`` and point chunks ``t1/<k>.bin``) of any
release the catalog knows, draft or published; the pages' scripts under ``/static/``. GET and HEAD
only, nothing outside those folders whatever the path or a symlink says."""

from __future__ import annotations

import html
import http.server
import io
import json
import logging
import mimetypes
import os
import re
import socket
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from importlib.resources import files
from pathlib import Path
from typing import Any, cast
from urllib.parse import parse_qs, quote, unquote, urlsplit

from siteline.errors import SitelineError
from siteline.previews.browser import browser_page
from siteline.previews.cloud import DEFAULT_BUDGET, CloudPlan, PairCloud
from siteline.records.release import Manifest
from siteline.release.manifest import read_manifest
from siteline.stores import layout

log = logging.getLogger(__name__)
SERVED = ("previews", "releases")
STATIC = "/static"
# the largest point budget a viewer may ask for
MAX_BUDGET = 20_000_000
# how many pairs' plans (open readers and their node plans) the server keeps
OPEN_PAIRS = 4
_ROUTE = re.compile(r"^/(browse|3d)/([^/]+)/([^/]+)/(.*)$")
# a number in a path: ASCII digits only (str.isdigit and int() take superscripts and other scripts)
_NUMBER = re.compile(r"[0-9]+", re.ASCII)
# an absolute path in an error's text (told by its last part only: a response never names the disk)
_ABSOLUTE = re.compile(r"(?:[A-Za-z]:)?(?:[/\\][^/\\\s'\"]+)+[/\\]?")
# a connection idle this long between two reads is closed (seconds)
IDLE_TIMEOUT_S = 20.0
# a request (its line and headers) must arrive whole within this many seconds of the server's
# starting to wait for it, however slowly its bytes trickle in; then its connection is closed
REQUEST_DEADLINE_S = 10.0
# how often the server looks for requests past their deadline (seconds)
REAP_EVERY_S = 0.25
# requests answered at once (a request holds one of these only once it has arrived whole); more are
# answered 503
MAX_CONNECTIONS = 64
# connections open at once, waiting for their request or answered; more are answered 503 and closed
MAX_PENDING = 512
# the longest path (characters) and path segment (UTF-8 bytes, a file name's limit) a request may name
MAX_PATH = 2048
MAX_SEGMENT = 255
# a pair or chunk number has at most this many digits
MAX_DIGITS = 9


@dataclass(frozen=True)
class ReleaseAccess:
    """How the server reaches releases beyond the published folders: ``locate(name, version)`` ->
    (release folder, status) (the catalog's ``release_location``), and ``open_pair(manifest,
    pair_id)`` -> the pair opened for the 3D viewer (``siteline.pipeline.pair_cloud``)."""

    locate: Callable[[str, str], tuple[Path, str]]
    open_pair: Callable[[Manifest, int], PairCloud]


class _Plans:
    """The plans of the pairs viewed last (at most :data:`OPEN_PAIRS`), each made once however many
    requests ask for it at the same time."""

    def __init__(self) -> None:
        self._plans: OrderedDict[tuple[Any, ...], CloudPlan] = OrderedDict()
        self._locks: dict[tuple[Any, ...], threading.Lock] = {}
        self._guard = threading.Lock()

    def get(self, key: tuple[Any, ...], make: Callable[[], CloudPlan]) -> CloudPlan:
        with self._guard:
            lock = self._locks.setdefault(key, threading.Lock())
        with lock:
            with self._guard:
                if key in self._plans:
                    self._plans.move_to_end(key)
                    return self._plans[key]
            plan = make()
            with self._guard:
                self._plans[key] = plan
                while len(self._plans) > OPEN_PAIRS:
                    self._plans.popitem(last=False)
            return plan


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


class _Manifests:
    """The manifests read last (at most :data:`OPEN_PAIRS` x 2), each read again only when its file
    changes: a page asks for dozens of chunks, and a release of 5,000 items has a manifest of megabytes."""

    def __init__(self) -> None:
        self._docs: OrderedDict[Path, tuple[tuple[int, int], Manifest]] = OrderedDict()
        self._guard = threading.Lock()

    def read(self, root: Path) -> Manifest:
        """``read_manifest(root)``, from memory when the file is the one read before."""
        try:
            st = (root / "manifest.json").stat()
            stamp = (st.st_mtime_ns, st.st_size)
        except OSError:
            return read_manifest(root)  # says what is wrong
        with self._guard:
            hit = self._docs.get(root)
            if hit is not None and hit[0] == stamp:
                self._docs.move_to_end(root)
                return hit[1]
        doc = read_manifest(root)
        with self._guard:
            self._docs[root] = (stamp, doc)
            while len(self._docs) > 2 * OPEN_PAIRS:
                self._docs.popitem(last=False)
        return doc


def _public(text: str) -> str:
    """An error's text as a response or a log line may hold it: each absolute path replaced by its
    last part (a file's name, never where the disk keeps it)."""
    return _ABSOLUTE.sub(lambda m: Path(m[0].rstrip("/\\")).name or "/", text)


def _number(text: str) -> int | None:
    """The number ``text`` spells in ASCII digits, at most :data:`MAX_DIGITS` of them; else None."""
    return int(text) if len(text) <= MAX_DIGITS and _NUMBER.fullmatch(text) else None


def _inside(root: Path, rel: str) -> Path | None:
    """``root/rel`` when ``rel`` names a file that lies inside ``root`` (no hidden part, no way out)."""
    parts = [p for p in rel.split("/") if p]
    if not parts or any(p.startswith(".") for p in parts):
        return None
    target = root.joinpath(*parts)
    real, top = os.path.realpath(target), os.path.realpath(root)
    return target if real.startswith(top + os.sep) and os.path.isfile(real) else None


class PreviewHandler(http.server.SimpleHTTPRequestHandler):
    """GET and HEAD of files under the served folders and of the browser's and viewer's routes;
    every other method is refused (501)."""

    home: Path
    timeout = IDLE_TIMEOUT_S  # socket timeout: an idle or half-sent request is closed
    _serving = False  # whether this request holds one of the server's answer slots

    def __init__(
        self, *args: Any, home: Path, access: ReleaseAccess | None = None, plans: _Plans | None = None,
        manifests: _Manifests | None = None, **kwargs: Any,
    ) -> None:  # fmt: skip
        self.home = home
        self.access = access
        self.plans = plans or _Plans()
        self.manifests = manifests or _Manifests()
        super().__init__(*args, directory=str(home), **kwargs)

    def handle_one_request(self) -> None:
        """One request: it must arrive whole within the server's deadline (:class:`PreviewServer`
        closes its connection after), then holds an answer slot while it is answered."""
        server = self._server
        server.watch(self.connection, self.client_address)
        try:
            super().handle_one_request()
        finally:
            server.unwatch(self.connection)
            if self._serving:
                self._serving = False
                server.answering.release()

    def parse_request(self) -> bool:
        """The request line and headers, read: answered 503 when every answer slot is taken, nothing
        when the server closed the connection at its deadline."""
        server = self._server
        if not server.unwatch(self.connection):  # closed at the deadline: nothing more to say
            self.close_connection = True
            return False
        if not super().parse_request():
            return False
        if not server.answering.acquire(blocking=False):
            log.info(
                "previews: %s answered 503: %d requests are being answered",
                self.client_address[0],
                server.limit,
            )
            self.send_error(503, "too many requests at once: try again")
            return False
        self._serving = True
        return True

    @property
    def _server(self) -> PreviewServer:
        return cast(PreviewServer, self.server)  # only that server makes these handlers

    def _send(self, body: bytes, content_type: str, status: int = 200, cache: bool = False) -> io.BytesIO:
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        if cache:
            self.send_header("Cache-Control", "public, max-age=86400")
        self.end_headers()
        return io.BytesIO(body)

    def _text(self, status: int, message: str) -> io.BytesIO:
        """A refusal in words (plain text: the viewer's script shows it)."""
        return self._send((message + "\n").encode(), "text/plain; charset=utf-8", status)

    def _locate(self, name: str, version: str) -> tuple[Path, str]:
        """The folder and status of release ``name`` ``version``: from the catalog when the server has
        one, else a published release under SITELINE_HOME. LookupError when there is none."""
        if self.access is not None:
            return self.access.locate(name, version)
        root = layout.releases(self.home) / name / version
        if not (root / "manifest.json").is_file() or any(p.startswith(".") for p in (name, version)):
            raise LookupError(f"no published release {name} {version} under {layout.releases(self.home)}")
        return root, "published"

    def _index(self) -> io.BytesIO:
        """The home page: every published release with its browser and its pairs' 3D views."""
        rows = []
        top = layout.releases(self.home)
        for name in sorted(n for n in os.listdir(top) if not n.startswith(".")) if top.is_dir() else []:
            for version in sorted(
                v for v in os.listdir(top / name) if not v.startswith(".") and (top / name / v).is_dir()
            ):
                try:
                    pairs = [int(p["id"]) for p in self.manifests.read(top / name / version).lineage["pairs"]]
                except (SitelineError, KeyError, ValueError, OSError):
                    continue
                base = f"{quote(name)}/{quote(version)}"
                views = " ".join(f'<a href="/3d/{base}/{p}/">pair {p}</a>' for p in pairs)
                rows.append(
                    f'<li>{html.escape(name)} {html.escape(version)}: <a href="/browse/{base}/">browse</a>'
                    f' &middot; 3D: {views} &middot; <a href="/releases/{base}/">files</a></li>'
                )
        body = (
            "<html><head><title>siteline previews</title></head><body><h1>siteline</h1><h2>releases</h2>"
            f"<ul>{''.join(rows) or '<li>none published yet</li>'}</ul>"
            '<p><a href="/releases/">release files</a> &middot; <a href="/previews/">pair previews</a></p></body></html>'
        )
        return self._send(body.encode(), "text/html; charset=utf-8")

    def _static(self, rel: str) -> io.BytesIO:
        parts = [p for p in rel.split("/") if p]
        if not parts or any(p.startswith(".") for p in parts):
            return self._text(404, "no such file")
        node = files("siteline.previews").joinpath("static", *parts)
        if not node.is_file():
            return self._text(404, "no such file")
        kind = mimetypes.guess_type(parts[-1])[0] or "application/octet-stream"
        if parts[-1].endswith(".js"):
            kind = "text/javascript; charset=utf-8"
        return self._send(node.read_bytes(), kind, cache=True)

    def _release_route(self, kind: str, name: str, version: str, rest: str) -> io.BytesIO:
        head, _, tail = rest.partition("/")
        pair_id = _number(head)
        if kind == "3d" and pair_id is None:
            return self._text(
                400,
                f"/3d/{name}/{version}/<pair>/: the pair is a number of at most {MAX_DIGITS} digits (0-9)",
            )
        try:
            root, status = self._locate(name, version)
        except LookupError:
            return self._text(404, f"no release {name} {version}")
        try:
            doc = self.manifests.read(root)
        except (SitelineError, OSError) as exc:
            log.info("previews: release %s %s: %s", name, version, _public(str(exc)))
            return self._text(404, f"release {name} {version} cannot be read: {_public(str(exc))}")
        base = f"/{kind}/{quote(name)}/{quote(version)}"
        browse = f"/browse/{quote(name)}/{quote(version)}/"
        if kind == "browse":
            if rest == "":
                page = browser_page(doc, f"{base}/files", f"/3d/{quote(name)}/{quote(version)}", status)
                return self._send(page.encode(), "text/html; charset=utf-8")
            if rest.startswith("files/") and (path := _inside(root, rest[len("files/") :])) is not None:
                kind_ = mimetypes.guess_type(path.name)[0] or "application/octet-stream"
                return self._send(path.read_bytes(), kind_, cache=status == "published")
            return self._text(404, f"release {name} {version} has no {rest}")
        pair = int(pair_id or 0)
        if tail == "":
            page = _viewer_page(f"{name} {version} ({status}): pair {pair} in 3D", f"{base}/{pair}")
            return self._send(page.encode(), "text/html; charset=utf-8")
        if self.access is None:
            return self._text(
                503, "the 3D viewer reads the scenes through the catalog: run `siteline previews serve`."
            )
        query = parse_qs(urlsplit(self.path).query)
        try:
            budget = int(query.get("budget", [DEFAULT_BUDGET])[0])
        except ValueError:
            return self._text(400, "budget: a number of points")
        if not 1000 <= budget <= MAX_BUDGET:
            return self._text(400, f"budget: between 1000 and {MAX_BUDGET} points, not {budget}")
        try:
            plan = self.plans.get(
                (str(root), doc.created, pair, budget),
                lambda: self.access.open_pair(doc, pair).plan(budget),  # type: ignore[union-attr]
            )
        except (SitelineError, OSError) as exc:
            log.info("previews: release %s %s pair %d: %s", name, version, pair, _public(str(exc)))
            return self._text(
                404, f"release {name} {version}: pair {pair} cannot be shown: {_public(str(exc))}"
            )
        if tail == "plan.json":
            return self._send(json.dumps(plan.to_dict(browse)).encode(), "application/json")
        m = re.fullmatch(rf"t([12])/([0-9]{{1,{MAX_DIGITS}}})\.bin", tail, re.ASCII)
        if m is None:
            return self._text(404, f"pair {pair} in 3D has no {tail}")
        try:
            data = plan.chunk(int(m[1]), int(m[2]))
        except (IndexError, SitelineError, OSError) as exc:
            return self._text(404, f"release {name} {version} pair {pair}: {_public(str(exc))}")
        return self._send(data, "application/octet-stream", cache=status == "published")

    def send_head(self) -> io.BufferedIOBase | io.BytesIO | None:  # type: ignore[override]
        path = unquote(urlsplit(self.path).path)
        if (
            "\x00" in path
            or len(path) > MAX_PATH
            or any(len(p.encode("utf-8", "surrogatepass")) > MAX_SEGMENT for p in path.split("/"))
        ):
            return self._text(
                400,
                f"a path without NUL bytes, of at most {MAX_PATH} characters and {MAX_SEGMENT} bytes a segment",
            )
        try:
            return self._route(path)
        except Exception as exc:  # a request must get an answer, and the log one line without the disk
            log.error("previews: %s failed: %s: %s", _public(path), type(exc).__name__, _public(str(exc)))
            log.debug("previews: %s failed", path, exc_info=True)
            return self._text(500, f"{type(exc).__name__}: the server could not answer this request")

    def _route(self, path: str) -> io.BufferedIOBase | io.BytesIO | None:
        if path in ("/", ""):
            return self._index()
        if path == "/favicon.ico":
            return self._send(b"", "image/x-icon", 204)
        if path.startswith(STATIC + "/"):
            return self._static(path[len(STATIC) + 1 :])
        if (m := _ROUTE.match(path)) is not None:
            return self._release_route(*m.groups())
        if path in ("/browse", "/3d") or path.startswith(("/browse/", "/3d/")):
            return self._text(404, f"{path}: use /browse/<name>/<version>/ or /3d/<name>/<version>/<pair>/")
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


def _viewer_page(title: str, base: str) -> str:
    template = files("siteline.previews").joinpath("static/viewer.html").read_text()
    return (
        template.replace("{{TITLE}}", html.escape(title))
        .replace("{{BASE}}", base)
        .replace("{{STATIC}}", STATIC)
    )


class PreviewServer(http.server.ThreadingHTTPServer):
    """A thread per connection, at most ``pending`` connections open (the next is answered 503 and
    closed) and ``limit`` requests answered at once (a request takes a slot only once it has
    arrived whole; the next is answered 503). A request must arrive whole within ``deadline_s`` of
    the server's starting to wait for it: a watcher thread closes the connection of one that has
    not, so clients that trickle their bytes (or send none) hold a connection for ``deadline_s`` at
    most and never an answer slot. A client that goes away mid-answer, or is closed at its
    deadline, is one line in the log, not a traceback."""

    daemon_threads = True
    # connections the kernel queues before they are accepted (the standard library's 5 made a burst of
    # 100 wait seconds for SYN retries)
    request_queue_size = 256

    def __init__(
        self,
        address: tuple[str, int],
        handler: Callable[..., Any],
        limit: int = MAX_CONNECTIONS,
        pending: int = MAX_PENDING,
        deadline_s: float = REQUEST_DEADLINE_S,
    ) -> None:
        super().__init__(address, handler)
        self.limit = limit
        self.slots = threading.BoundedSemaphore(pending)
        self.answering = threading.BoundedSemaphore(limit)
        self.deadline_s = deadline_s
        self._waiting: dict[socket.socket, tuple[float, str]] = {}
        self._closed_at_deadline: set[socket.socket] = set()
        self._guard = threading.Lock()
        self._stop = threading.Event()
        threading.Thread(target=self._close_late, name="previews-deadline", daemon=True).start()

    def watch(self, conn: socket.socket, client_address: Any) -> None:
        """Start the deadline of the request ``conn`` is about to send."""
        with self._guard:
            self._waiting[conn] = (time.monotonic() + self.deadline_s, str(client_address[0]))

    def unwatch(self, conn: socket.socket) -> bool:
        """Stop ``conn``'s deadline; False when the server already closed it there."""
        with self._guard:
            self._waiting.pop(conn, None)
            return conn not in self._closed_at_deadline

    def _close_late(self) -> None:
        while not self._stop.wait(REAP_EVERY_S):
            now = time.monotonic()
            with self._guard:
                late = [(c, who) for c, (due, who) in self._waiting.items() if due <= now]
                for conn, _ in late:
                    del self._waiting[conn]
                    self._closed_at_deadline.add(conn)
            for conn, who in late:
                log.info(
                    "previews: %s did not send a whole request within %g s: closed", who, self.deadline_s
                )
                try:
                    conn.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass

    def server_close(self) -> None:
        self._stop.set()
        super().server_close()

    def shutdown_request(self, request: Any) -> None:
        with self._guard:
            self._closed_at_deadline.discard(request)
        super().shutdown_request(request)

    def process_request(self, request: Any, client_address: Any) -> None:
        if not self.slots.acquire(blocking=False):
            try:
                request.sendall(b"HTTP/1.0 503 Service Unavailable\r\nContent-Type: text/plain\r\n"
                                b"Connection: close\r\n\r\ntoo many connections: try again\n")  # fmt: skip
            except OSError:
                pass
            self.shutdown_request(request)
            return
        try:
            super().process_request(request, client_address)
        except BaseException:
            self.slots.release()
            raise

    def process_request_thread(self, request: Any, client_address: Any) -> None:
        try:
            super().process_request_thread(request, client_address)
        finally:
            self.slots.release()

    def handle_error(self, request: Any, client_address: Any) -> None:
        import sys

        exc = sys.exc_info()[1]
        with self._guard:
            if request in self._closed_at_deadline:  # said when it was closed
                return
        if isinstance(exc, ConnectionError | TimeoutError):
            log.info("previews: %s went away (%s)", client_address[0], type(exc).__name__)
            return
        log.exception("previews: a request of %s failed", client_address[0])


def make_server(
    home: Path, host: str, port: int, access: ReleaseAccess | None = None, limit: int = MAX_CONNECTIONS,
    pending: int = MAX_PENDING, deadline_s: float = REQUEST_DEADLINE_S,
) -> PreviewServer:  # fmt: skip
    """A server of ``home``'s previews and releases on ``host``:``port`` (not started); ``access``:
    how to reach drafts and the scenes behind a release (None: published releases, no 3D viewer);
    ``limit``: requests answered at once, ``pending``: connections open at once, ``deadline_s``:
    seconds a request has to arrive whole (:class:`PreviewServer`)."""
    layout.previews(home).mkdir(parents=True, exist_ok=True)
    layout.releases(home).mkdir(parents=True, exist_ok=True)
    handler = partial(PreviewHandler, home=Path(home), access=access, plans=_Plans(), manifests=_Manifests())
    return PreviewServer((host, port), handler, limit, pending, deadline_s)
