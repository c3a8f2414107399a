"""Files written and read around the page cache (siteline.stores.directio) and the store's copy to disk:
the same bytes as a plain write and read, at any size and offset, on a file system with direct I/O
and on one without (tmpfs)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from siteline.stores import directio

SHM = Path("/dev/shm")


def _folders(tmp_path: Path) -> list[Path]:
    """A folder on the tests' file system and, where there is one, on tmpfs (no O_DIRECT there)."""
    out = [tmp_path]
    if SHM.is_dir() and os.access(SHM, os.W_OK):
        shm = SHM / f"siteline-test-{os.getpid()}-{tmp_path.name}"
        shm.mkdir()
        out.append(shm)
    return out


@pytest.fixture
def folders(tmp_path: Path):
    out = _folders(tmp_path)
    yield out
    for f in out[1:]:
        for p in f.iterdir():
            p.unlink()
        f.rmdir()


def test_appended_blocks_make_the_file_a_plain_write_makes(folders: list[Path]) -> None:
    rng = np.random.default_rng(0)
    sizes = [0, 1, 27, 4095, 4096, 4097, 100_003, 3 * 4096, 2_000_001, 5]
    pieces = [rng.integers(0, 256, n, dtype=np.uint8) for n in sizes]
    want = np.concatenate(pieces).tobytes()
    for folder in folders:
        path = str(folder / "run.bin")
        at, tail = 0, b""
        for piece in pieces:
            written = at + len(tail) + piece.nbytes
            tail = directio.append_blocks(path, at, tail, piece.data)
            assert len(tail) < directio.BLOCK and (written - len(tail)) % directio.BLOCK == 0
            at = written - len(tail)
        directio.finish_blocks(path, at, tail)
        assert Path(path).read_bytes() == want, folder


def test_read_blocks_fills_views_from_any_offset_and_stops_at_the_end(folders: list[Path]) -> None:
    data = np.random.default_rng(1).integers(0, 256, 3 * 4096 + 777, dtype=np.uint8).tobytes()
    for folder in folders:
        path = folder / "data.bin"
        path.write_bytes(data)
        for offset, lengths in [
            (0, [10]),
            (4095, [1, 2, 4096]),
            (5000, [0, 300, 7000]),
            (len(data) - 5, [3, 9]),
        ]:
            views = [memoryview(bytearray(n)) for n in lengths]
            got = directio.read_blocks(str(path), offset, views)
            want = data[offset : offset + sum(lengths)]
            assert got == len(want), (folder, offset)
            assert b"".join(bytes(v) for v in views)[:got] == want


def test_copy_to_disk_copies_every_size(folders: list[Path]) -> None:
    rng = np.random.default_rng(2)
    for folder in folders:
        for n in (0, 1, 4096, (8 << 20) + 3):
            src = folder / f"src-{n}"
            src.write_bytes(rng.integers(0, 256, n, dtype=np.uint8).tobytes())
            dest = folder / f"dest-{n}"
            directio.copy_to_disk(src, dest)
            assert dest.read_bytes() == src.read_bytes(), (folder, n)
