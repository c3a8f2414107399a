"""The preview route the UI loads images from is read-only and shows pair previews and published
releases only; release and pair artifacts say what a person watching the service needs."""

from __future__ import annotations

import json
import threading

import httpx
import pytest

from siteline.config import Settings
from siteline.previews.images import url_of
from siteline.previews.markdown import release_markdown
from siteline.previews.server import make_server
from siteline.records.release import Manifest, ReleaseInfo

PNG = b"\x89PNG\r\n\x1a\n" + b"0" * 32


@pytest.fixture
def served(tmp_path):
    home = tmp_path / "home"
    (home / "previews" / "pairs" / "pair-1" / "abc").mkdir(parents=True)
    (home / "previews" / "pairs" / "pair-1" / "abc" / "samples.png").write_bytes(PNG)
    (home / "releases" / "r" / "1.0.0").mkdir(parents=True)
    (home / "releases" / "r" / "1.0.0" / "montage.png").write_bytes(PNG)
    (home / "releases" / "r" / ".drafts" / "2.0.0").mkdir(parents=True)
    (home / "releases" / "r" / ".drafts" / "2.0.0" / "montage.png").write_bytes(PNG)
    (home / "catalog.sqlite").write_bytes(b"secret")
    (tmp_path / "outside.png").write_bytes(PNG)
    (home / "previews" / "escape.png").symlink_to(tmp_path / "outside.png")
    server = make_server(home, "127.0.0.1", 0)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{server.server_address[1]}", home
    server.shutdown()
    server.server_close()


def test_previews_and_published_releases_are_served_read_only(served) -> None:
    base, _ = served
    ok = httpx.get(f"{base}/previews/pairs/pair-1/abc/samples.png")
    assert ok.status_code == 200 and ok.content == PNG and ok.headers["content-type"] == "image/png"
    assert httpx.get(f"{base}/releases/r/1.0.0/montage.png").status_code == 200
    listing = httpx.get(f"{base}/releases/r/").text
    assert "1.0.0" in listing and ".drafts" not in listing
    for path in ("/releases/r/.drafts/2.0.0/montage.png", "/catalog.sqlite", "/releases/../catalog.sqlite",
                 "/releases/%2e%2e/catalog.sqlite", "/previews/escape.png", "/stores/", "/releases/r/9.9.9/x.png"):  # fmt: skip
        assert httpx.get(base + path).status_code == 404, path
    for method in ("PUT", "POST", "DELETE"):
        assert httpx.request(method, f"{base}/releases/r/1.0.0/montage.png").status_code == 501


def test_urls_point_at_the_preview_route(tmp_path) -> None:
    settings = Settings(home=tmp_path, database_url="sqlite://", preview_url="http://host:4201")
    assert url_of(settings, tmp_path / "releases" / "a b" / "1.0.0" / "montage.png") == (
        "http://host:4201/releases/a%20b/1.0.0/montage.png"
    )


def test_the_release_artifact_says_why_where_and_how_big() -> None:
    item = {"id": "p1_v0", "split": "train", "pair": 1, "view": 0, "coverage": 0.9, "valid": 0.6, "change_ratio": 0.1,
            "size_px": [515, 386], "padded_px": [544, 416]}  # fmt: skip
    doc = {
        "format": "siteline-release/2",
        "name": "r",
        "version": "2.0.0",
        "created": "2026-11-28",
        "code_version": "0",
        "splits": {"train": [1], "val": [], "test": [1]},
        "files": [],
        "items": [item, item | {"id": "p1_v1", "view": 1, "split": "test", "valid": 0.3}],
        "lineage": {
            "parameters": {
                "scale": 0.78,
                "point_size_px": 3,
                "views": 24,
                "min_coverage": 0.5,
                "min_valid": 0.25,
            },
            "release_params": {"derived": {"scale": "auto: 512 px long side from the smallest camera"}},
            "pairs": [{"id": 1, "t1": 1, "t2": 2, "radius_m": 0.38, "label_sets": {"t1": 2, "t2": 1}}],
            "scenes": [
                {
                    "id": 1,
                    "capture_time": "2024-11-27",
                    "label_set_version": 2,
                    "label_set_source": "import x.las",
                }
            ],
        },
        "stats": {"class_balance": {"train": {"changed": 10, "unchanged": 20, "ignore": 5}}},
    }
    info = ReleaseInfo(
        "r", "2.0.0", "published", "/h/releases/r/2.0.0", 2, "ab" * 32, {}, "scene 1 label set v1 -> v2"
    )
    md = release_markdown(info, Manifest.from_dict(doc), "http://h:4201/releases/r/2.0.0/montage.png")
    assert "![montage of r 2.0.0" in md and "(http://h:4201/releases/r/2.0.0/montage.png)" in md
    assert "| why this version | scene 1 label set v1 -> v2 |" in md
    assert "515 x 386 px (stored padded to 544 x 416)" in md and "0.78 (auto: 512 px" in md
    assert "| valid fraction | mean 0.45 (min 0.30, max 0.60) |" in md
    assert "| 1 | 1 -> 2 | v2, v1 | 2 | 0.380 |" in md and "| 1 | 2024-11-27 | v2 | import x.las |" in md
    # with the preview server's address: links to the release browser and to each pair in 3D
    md = release_markdown(
        info, Manifest.from_dict(doc), "http://h:4201/releases/r/2.0.0/montage.png", "http://h:4201"
    )
    assert (
        "[browse every item](http://h:4201/browse/r/2.0.0/)" in md
        and "[pair 1](http://h:4201/3d/r/2.0.0/1/)" in md
    )


def test_a_stopped_run_says_why_in_words() -> None:
    from datetime import UTC, datetime

    from siteline.previews.markdown import RunEvent, stopped_markdown

    at = datetime(2026, 11, 27, 5, 12, 36, tzinfo=UTC)
    why = "no heartbeat for 50 s: its process or machine died"
    md = stopped_markdown("scene-1-labels-v3", [RunEvent(at, "Crashed", why, 1), RunEvent(at, "AwaitingRetry", "", 1)],
                          "40 % done (pair 1: renders 3 of 6)", 3)  # fmt: skip
    assert md.startswith("# Why scene-1-labels-v3 stopped") and f"**{why}**" in md and "went down" in md
    assert "rescheduled (attempt 2 of 3)" in md and "Where it was: 40 % done (pair 1: renders 3 of 6)." in md
    md = stopped_markdown(
        "r", [RunEvent(at, "Crashed", "Flow run infrastructure exited with status -9", 3)], None, 3
    )
    assert (
        "crashed 3 times, the most the service retries" in md
        and "rescheduled" not in md
        and "went down" not in md
    )


def _raw(base: str, request: bytes, timeout: float = 5.0) -> bytes:
    """Send ``request`` as is on a new connection; what comes back before the server closes it."""
    import socket

    host, port = base.removeprefix("http://").split(":")
    with socket.create_connection((host, int(port)), timeout=timeout) as sock:
        sock.sendall(request)
        chunks = []
        while chunk := sock.recv(65536):
            chunks.append(chunk)
    return b"".join(chunks)


def test_malformed_paths_and_numbers_get_400_never_500_or_silence(served) -> None:
    base, _ = served
    for path in (b"/releases/r/1.0.0/mon%00tage.png", b"/static/" + b"a" * 300 + b".js",
                 b"/3d/r/1.0.0/" + b"9" * 5000 + b"/plan.json", b"/" + b"x/" * 1500):  # fmt: skip
        answer = _raw(base, b"GET " + path + b" HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
        assert answer.startswith(b"HTTP/1.0 400") or answer.startswith(b"HTTP/1.1 400"), (
            path[:40],
            answer[:80],
        )
        assert b"Traceback" not in answer and b"Error" not in answer.split(b"\r\n\r\n", 1)[-1]


def test_idle_and_half_sent_connections_are_closed_and_their_number_capped(tmp_path, monkeypatch) -> None:
    import socket
    import time

    from siteline.previews import server as srv

    monkeypatch.setattr(srv.PreviewHandler, "timeout", 0.5)
    home = tmp_path / "home"
    server = make_server(home, "127.0.0.1", 0, pending=3)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    port = server.server_address[1]
    try:
        idle = [socket.create_connection(("127.0.0.1", port), timeout=5) for _ in range(3)]
        idle[0].sendall(b"GET /previews/ HTTP/1.1\r\nHo")  # half-sent
        time.sleep(0.2)
        # a fourth while three are held: answered 503 at once, and closed
        assert _raw(f"http://127.0.0.1:{port}", b"GET / HTTP/1.0\r\n\r\n").startswith(b"HTTP/1.0 503")
        time.sleep(1.0)
        for sock in idle:  # each closed by the server after its idle timeout
            assert sock.recv(65536) == b""
            sock.close()
        time.sleep(0.2)
        # their slots are free again
        assert httpx.get(f"http://127.0.0.1:{port}/", timeout=5).status_code == 200
    finally:
        server.shutdown()
        server.server_close()


def test_a_client_gone_mid_answer_is_one_line_in_the_log(tmp_path, caplog) -> None:
    import logging

    server = make_server(tmp_path / "home", "127.0.0.1", 0)
    try:
        with caplog.at_level(logging.INFO, logger="siteline.previews.server"):
            try:
                raise BrokenPipeError(32, "Broken pipe")
            except BrokenPipeError:
                server.handle_error(None, ("10.0.0.7", 5555))
        [record] = caplog.records
        assert "went away" in record.getMessage() and record.exc_info is None
    finally:
        server.server_close()


def test_clients_that_trickle_never_lock_out_a_normal_request(tmp_path, caplog) -> None:
    """80 sockets that send a request's bytes one at a time, every 0.3 s, and 20 that send nothing:
    a normal request is answered at once all along, each of them is closed at the request deadline
    (1.5 s here) however it trickles, and each is one line in the log, never a traceback."""
    import logging
    import socket
    import time

    server = make_server(tmp_path / "home", "127.0.0.1", 0, deadline_s=1.5)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    port = server.server_address[1]
    try:
        with caplog.at_level(logging.INFO, logger="siteline.previews.server"):
            slow = [socket.create_connection(("127.0.0.1", port), timeout=5) for _ in range(100)]
            started = time.monotonic()
            answered, closed = [], set()
            request = b"GET / HTTP/1.1\r\nHost: x\r\n" + b"X-Slow: " + b"a" * 200
            for k in range(12):  # 3.6 s of trickling
                for i, sock in enumerate(slow[:80]):
                    if i in closed:
                        continue
                    try:
                        sock.sendall(request[k : k + 1])
                    except OSError:
                        closed.add(i)
                t0 = time.monotonic()
                answered.append(
                    (httpx.get(f"http://127.0.0.1:{port}/", timeout=5).status_code, time.monotonic() - t0)
                )
                time.sleep(0.3)
            assert all(code == 200 and took < 1.0 for code, took in answered), answered
            for sock in slow:  # each was closed by the server at its deadline
                sock.settimeout(3.0)
                try:
                    assert sock.recv(65536) == b""
                except ConnectionResetError:
                    pass
                sock.close()
            assert time.monotonic() - started < 8.0
            time.sleep(0.3)
        late = [r for r in caplog.records if "did not send a whole request" in r.getMessage()]
        assert len(late) == 100 and all(r.exc_info is None for r in caplog.records)
        assert not [r for r in caplog.records if r.levelno >= logging.WARNING]
    finally:
        server.shutdown()
        server.server_close()


def test_requests_answered_at_once_are_capped_and_the_next_gets_503(tmp_path, monkeypatch) -> None:
    import time

    from siteline.previews import server as srv

    index = srv.PreviewHandler._index

    def slow_index(self):  # noqa: ANN001, ANN202
        time.sleep(1.0)
        return index(self)

    monkeypatch.setattr(srv.PreviewHandler, "_index", slow_index)
    server = make_server(tmp_path / "home", "127.0.0.1", 0, limit=1)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    base = f"http://127.0.0.1:{server.server_address[1]}/"
    try:
        first = threading.Thread(target=httpx.get, args=(base,), kwargs={"timeout": 5})
        first.start()
        time.sleep(0.3)
        busy = httpx.get(base, timeout=5)
        assert busy.status_code == 503 and "try again" in busy.text
        first.join()
        assert httpx.get(base, timeout=5).status_code == 200  # the slot is free again
    finally:
        server.shutdown()
        server.server_close()


def test_numbers_are_ascii_digits_and_segments_are_capped_in_bytes(served, caplog) -> None:
    """A pair index in another script's digits (superscripts, circled, Arabic-Indic, full-width,
    mathematical) is 400, never pair 1 or a 500; a path segment of 200 x 'é' (400 bytes) is 400;
    none of it is more than one log line."""
    import logging
    from urllib.parse import quote

    base, _ = served
    with caplog.at_level(logging.DEBUG, logger="siteline.previews.server"):
        for digit in ("²", "¹", "①", "١", "１", "𝟏"):
            for path in (f"/3d/r/1.0.0/{digit}/", f"/3d/r/1.0.0/{digit}/plan.json"):
                answer = _raw(base, f"GET {quote(path)} HTTP/1.0\r\n\r\n".encode())
                assert answer.startswith(b"HTTP/1.0 400"), (path, answer[:60])
        answer = _raw(base, f"GET /static/{quote('é' * 200)}.js HTTP/1.0\r\n\r\n".encode())
        assert answer.startswith(b"HTTP/1.0 400") and b"bytes a segment" in answer
        assert _raw(base, f"GET /static/{quote('é' * 100)}.js HTTP/1.0\r\n\r\n".encode()).startswith(
            b"HTTP/1.0 404"
        )
    assert all(r.exc_info is None and "Traceback" not in r.getMessage() for r in caplog.records)


def test_not_found_bodies_and_log_lines_never_name_the_disk(tmp_path, caplog) -> None:
    """A draft whose manifest is missing, not JSON or a list, a release folder gone, a pair whose
    tile store is gone: 404 naming the release and version, never a path outside the release, in
    the body or the log."""
    import logging

    from siteline.errors import TileError
    from siteline.previews.server import ReleaseAccess

    home = tmp_path / "home"
    drafts = tmp_path / "home" / "releases" / "r" / ".drafts"
    for v, text in (("1.0.0", None), ("2.0.0", "{not json"), ("3.0.0", "[1, 2]")):
        (drafts / v).mkdir(parents=True)
        if text is not None:
            (drafts / v / "manifest.json").write_text(text)
    (drafts / "5.0.0").mkdir()
    good = {"format": 2, "name": "r", "version": "5.0.0", "created": "2026-11-28T00:00:00+00:00",
            "code_version": "test", "files": [], "splits": {"train": [], "val": [], "test": []}, "items": [],
            "lineage": {"pairs": []}}  # fmt: skip
    (drafts / "5.0.0" / "manifest.json").write_text(json.dumps(good))

    def locate(name: str, version: str):  # noqa: ANN202
        if version == "4.0.0":
            return home / "releases" / name / version, "published"  # its folder is gone
        return drafts / version, "draft"

    def open_pair(doc, pair):  # noqa: ANN001, ANN202
        raise TileError(f"{home}/stores/tiles/scene-{pair}.zarr is not a siteline tile store.")

    server = make_server(home, "127.0.0.1", 0, access=ReleaseAccess(locate, open_pair))
    threading.Thread(target=server.serve_forever, daemon=True).start()
    base = f"http://127.0.0.1:{server.server_address[1]}"
    try:
        with caplog.at_level(logging.DEBUG, logger="siteline.previews.server"):
            for path in ("/browse/r/1.0.0/", "/browse/r/2.0.0/", "/browse/r/3.0.0/", "/browse/r/4.0.0/",
                         "/3d/r/4.0.0/1/plan.json", "/3d/r/5.0.0/1/plan.json"):  # fmt: skip
                r = httpx.get(base + path, timeout=5)
                assert r.status_code == 404, (path, r.status_code, r.text)
                assert "release r" in r.text and str(tmp_path) not in r.text and "/tmp" not in r.text, (
                    path,
                    r.text,
                )
        assert good and all(str(tmp_path) not in rec.getMessage() for rec in caplog.records)
        assert all(rec.exc_info is None for rec in caplog.records)
    finally:
        server.shutdown()
        server.server_close()
