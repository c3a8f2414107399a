"""The store layer on a local folder and on an object store (a local S3 server): the same contract."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np
import pytest

from siteline.config import load_settings
from siteline.errors import StoreError
from siteline.stores import MARKER, FsspecStore, LocalStore, Store, join, open_store


@pytest.fixture(params=["local", "s3"])
def store(request: pytest.FixtureRequest, tmp_path: Path) -> Store:
    url = str(tmp_path / "stores") if request.param == "local" else request.getfixturevalue("s3_store")
    st = open_store(url, tmp_path / "staging")
    st.ensure()
    return st


def _listing(uri: str) -> list[str]:
    """Every file under ``uri``, relative, sorted (local or remote)."""
    if isinstance(open_store(uri), LocalStore):
        root = Path(uri)
        return sorted(p.relative_to(root).as_posix() for p in root.rglob("*") if p.is_file())
    import fsspec

    fs, path = fsspec.core.url_to_fs(uri)
    fs.invalidate_cache()
    return sorted(f[len(path) + 1 :] for f in fs.find(path))


def test_bytes_and_files_round_trip(store: Store, tmp_path: Path) -> None:
    uri = store.uri("blobs", "ab", "cdef")
    assert not store.exists(uri)
    store.put_bytes(b"hello", uri)
    assert store.exists(uri) and store.read_bytes(uri) == b"hello"
    src = tmp_path / "src.bin"
    src.write_bytes(b"x" * 1000)
    other = store.uri("blobs", "12", "3456")
    store.put_file(src, other)
    out = tmp_path / "back.bin"
    store.get_file(other, out)
    assert out.read_bytes() == src.read_bytes()
    store.remove(uri)
    assert not store.exists(uri)
    store.remove(uri)  # removing what is gone is fine
    with pytest.raises(StoreError, match="cdef"):
        store.read_bytes(uri)


def _tree(work: Path) -> None:
    import zarr

    g = zarr.open_group(str(work), mode="w")
    g.create_array("a", data=np.arange(100, dtype=np.int32), chunks=(10,))
    g.attrs["checksum"] = "abc"
    (work / "notes").mkdir()
    (work / "notes" / "summary.json").write_text("{}")


def test_publish_is_whole_and_readable(store: Store) -> None:
    uri = store.uri("tiles", "scene-1.zarr")
    with store.publish(uri) as work:
        assert not work.exists()
        _tree(work)
    assert store.is_complete(uri)
    files = _listing(uri)
    assert MARKER in files and "notes/summary.json" in files and "zarr.json" in files
    g = store.open_group(uri)
    assert g.attrs["checksum"] == "abc"
    np.testing.assert_array_equal(g["a"][:], np.arange(100))
    assert not list(store.staging.glob("publish-*"))  # staging is cleaned up


def test_failed_publish_leaves_nothing(store: Store) -> None:
    uri = store.uri("labels", "pair-1.zarr")
    with pytest.raises(RuntimeError, match="boom"), store.publish(uri) as work:
        _tree(work)
        raise RuntimeError("boom")
    assert not store.is_complete(uri)
    assert not store.exists(join(uri, "zarr.json"))
    if isinstance(store, LocalStore):
        assert not [p for p in Path(store.url, "labels").iterdir()]  # no hidden partial either
    assert not list(store.staging.glob("publish-*"))
    with pytest.raises(StoreError, match="nothing was built"), store.publish(uri):
        pass


def test_unfinished_upload_is_not_complete_and_is_replaced(store: Store) -> None:
    """A writer killed mid-upload leaves files without the marker: invisible, and replaced."""
    uri = store.uri("pairs", "pair-1", "d1")
    store.put_bytes(b"stale", join(uri, "A", "0000.png"))
    assert not store.is_complete(uri)
    with store.publish(uri) as work:
        (work / "B").mkdir(parents=True)
        (work / "B" / "0000.png").write_bytes(b"new")
    assert store.is_complete(uri)
    assert _listing(uri) == [MARKER, "B/0000.png"]


def test_a_complete_folder_is_kept(store: Store) -> None:
    """Two workers publishing the same (deterministic) folder: the first one stays."""
    uri = store.uri("pairs", "pair-2", "d1")
    for content in (b"first", b"second"):
        with store.publish(uri) as work:
            work.mkdir()
            (work / "f").write_bytes(content)
    assert store.read_bytes(join(uri, "f")) == b"first"
    store.remove(uri)
    assert not store.is_complete(uri) and not store.exists(join(uri, "f"))


def test_local_file_fetches_checks_and_caches(store: Store, tmp_path: Path) -> None:
    data = b"point cloud bytes"
    sha = hashlib.sha256(data).hexdigest()
    uri = store.uri("blobs", sha[:2], sha[2:])
    store.put_bytes(data, uri)
    path = store.local_file(uri, sha)
    assert path.read_bytes() == data
    if isinstance(store, FsspecStore):
        assert store.staging in path.parents
        store.remove(uri)
        assert store.local_file(uri, sha) == path  # served from the cache
        bad = store.uri("blobs", "00", "bad")
        store.put_bytes(b"damaged", bad)
        with pytest.raises(StoreError, match="does not match its checksum"):
            store.local_file(bad, "00" + "0" * 62)
    else:
        assert path == Path(uri)


def test_unknown_file_system_and_missing_bucket_are_clear(s3_endpoint: str, tmp_path: Path) -> None:
    with pytest.raises(StoreError, match="nosuchfs://bucket"):
        open_store("nosuchfs://bucket/x").exists("nosuchfs://bucket/x")
    with pytest.raises(StoreError, match="needs its bucket 'no-such-bucket'"):
        open_store("s3://no-such-bucket/stores", tmp_path).ensure()


def test_store_url_setting(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    env = {"SITELINE_HOME": str(tmp_path / "h")}
    assert load_settings(env).store.url == str(tmp_path / "h" / "stores")
    assert load_settings(env | {"SITELINE_STORE_URL": "s3://b/p/"}).store.url == "s3://b/p"
    monkeypatch.chdir(tmp_path)
    assert load_settings(env | {"SITELINE_STORE_URL": "shared"}).store.url == str(tmp_path / "shared")
    local = load_settings(env | {"SITELINE_STORE_URL": f"file://{tmp_path}/x"}).store
    assert local.url == f"{tmp_path}/x" and isinstance(local, LocalStore)


def test_cli_init_names_the_store(capsys, home, monkeypatch, s3_store) -> None:
    from sitehelpers import run_cli

    monkeypatch.setenv("SITELINE_STORE_URL", "s3://siteline-missing-bucket/stores")
    rc, _, err = run_cli(capsys, "init")
    assert rc != 0 and "needs its bucket 'siteline-missing-bucket'" in err
    monkeypatch.setenv("SITELINE_STORE_URL", s3_store)
    rc, out, _ = run_cli(capsys, "init")
    assert rc == 0 and f"stores at {s3_store}" in out.replace("\n", "")


def test_publish_clears_only_leftovers_of_dead_writers(tmp_path: Path) -> None:
    """A writer killed mid-build leaves its partial folder; the next publish clears it, but never the
    partial folder of a writer that is still running (another process, same host)."""
    import subprocess
    import sys

    store = open_store(str(tmp_path / "stores"), tmp_path / "staging")
    uri = store.uri("pairs", "pair-1", "d1")
    parent = Path(uri).parent
    script = (
        "import sys, time\n"
        "from siteline.stores import open_store\n"
        "st = open_store(sys.argv[1], sys.argv[2])\n"
        "with st.publish(sys.argv[3]) as work:\n"
        "    work.mkdir(); (work / 'f').write_bytes(b'x'); print('ready', flush=True); time.sleep(60)\n"
    )
    args = [sys.executable, "-c", script, store.url, str(tmp_path / "staging"), uri]
    dead = subprocess.Popen(args, stdout=subprocess.PIPE, text=True)
    live = subprocess.Popen(args, stdout=subprocess.PIPE, text=True)
    try:
        assert dead.stdout.readline().strip() == "ready" and live.stdout.readline().strip() == "ready"
        dead.kill()
        dead.wait()
        partials = sorted(p.name for p in parent.iterdir() if p.name.startswith(".d1.partial-"))
        assert len(partials) == 2
        with store.publish(uri) as work:
            work.mkdir()
            (work / "f").write_bytes(b"mine")
        left = sorted(p.name for p in parent.iterdir() if p.name.startswith(".d1.partial-"))
        assert left == [n for n in partials if f"+{live.pid}+" in n]  # the live writer's stays
        assert store.read_bytes(join(uri, "f")) == b"mine"
    finally:
        live.kill()
        live.wait()


def test_a_file_write_sweeps_dead_writers_temporaries_only(tmp_path: Path) -> None:
    """Blobs, cached downloads and every other file go through atomic_file: a killed writer's
    ``.<name>.tmp-<owner>`` is removed by the next write in that folder, a live writer's is kept."""
    import subprocess
    import sys

    from siteline.stores import write_file
    from siteline.stores.owners import owner_tag

    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    tag = owner_tag()
    dead = tmp_path / f".ab12.tmp-{tag.replace(f'+{os.getpid()}+', f'+{gone.pid}+')}"
    live = tmp_path / f".cd34.tmp-{tag.replace(f'+{os.getpid()}+', '+1+')}"  # pid 1 always runs
    dead.write_bytes(b"half")
    live.write_bytes(b"busy")
    write_file(tmp_path / "ef56", lambda fh: fh.write(b"whole"))
    assert not dead.exists() and live.read_bytes() == b"busy"
    assert (tmp_path / "ef56").read_bytes() == b"whole"


def test_publish_shared_is_all_or_nothing(store: Store) -> None:
    """What workers build straight into the store counts only once its marker is written; an error
    leaves nothing, and an empty build is refused."""
    import fsspec

    uri = store.uri("shared", "x.zarr")

    def put(target: str) -> None:
        fs, path = fsspec.core.url_to_fs(target)
        fs.makedirs(path, exist_ok=True)
        fs.pipe_file(f"{path}/zarr.json", b"{}")

    with pytest.raises(RuntimeError), store.publish_shared(uri) as target:
        put(target)
        raise RuntimeError("a worker died")
    assert not store.exists(uri) and not store.is_complete(uri)
    with store.publish_shared(uri) as target:
        put(target)
    assert store.is_complete(uri)
    with pytest.raises(StoreError), store.publish_shared(store.uri("shared", "empty.zarr")):
        pass


def test_a_staged_file_appears_only_on_commit(store: Store, tmp_path: Path) -> None:
    """stage_file does the copy first (beside other work) and the file appears whole only on
    commit; a discarded one leaves nothing, temporary files included."""
    source = tmp_path / "cloud.las"
    source.write_bytes(b"points" * 1000)
    uri = store.uri("blobs", "ab", "cdef")
    staged = store.stage_file(source, uri)
    assert not store.exists(uri)
    staged.commit()
    assert store.read_bytes(uri) == source.read_bytes()
    other = store.uri("blobs", "ab", "0123")
    store.stage_file(source, other).discard()
    assert not store.exists(other)
    if "://" not in store.url:
        assert sorted(p.name for p in (Path(store.url) / "blobs" / "ab").iterdir()) == ["cdef"]
