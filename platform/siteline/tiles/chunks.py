"""Inner chunks of a tile store's arrays read and written straight on a local disk: the layout
siteline writes (siteline.tiles.codecs: a 1-D chunk grid of shards, each an index at its end and inner
chunks of [transpose or fixed scale/offset], bytes, blosc) coded by blosc itself; reads decode several
chunks at once in threads.

zarr's codec pipeline (asyncio tasks through each codec in turn) gives the same arrays 3-6x slower on
such chunks (measured on the 8,000 points/m2 site: xyz 464 against 1,585 MB/s, classes 195 against
1,179 MB/s a core), and a view's read is mostly decoding; writing a tile's shards through it was half
of tiling a 5M-point file on one core (docs/performance.md). The bytes are zarr's own, shard for
shard (tested), so zarr reads what is written here and the other way round. An array of any other
layout, or in a store not on a local disk, is left to zarr (:func:`direct_chunks` gives None).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import cast

import google_crc32c
import numcodecs
import numpy as np
import zarr
from numcodecs import blosc
from zarr.codecs import BloscCodec, BytesCodec, Crc32cCodec, ShardingCodec, TransposeCodec
from zarr.codecs.numcodecs import FixedScaleOffset
from zarr.codecs.sharding import ShardingCodecIndexLocation
from zarr.storage import LocalStore

from siteline.errors import TileError

EMPTY = np.uint64(2**64 - 1)  # an inner chunk never written (its values are the fill value)
_POOL: list[ThreadPoolExecutor] = []
_POOL_LOCK = threading.Lock()
_SHUFFLE = {"noshuffle": blosc.NOSHUFFLE, "shuffle": blosc.SHUFFLE, "bitshuffle": blosc.BITSHUFFLE}


def _pool() -> ThreadPoolExecutor:
    """The threads chunks are decoded in (one a core; blosc releases the GIL while it decodes)."""
    with _POOL_LOCK:
        if not _POOL:
            cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
            _POOL.append(ThreadPoolExecutor(max(1, cores), thread_name_prefix="siteline-chunks"))
        return _POOL[0]


class DirectChunks:
    """The inner chunks of one sharded array on a local disk (see the module docstring): ``read``
    returns chunk ``i``'s rows ((c, ...) in the array's dtype; the last chunk cut at the array's
    end), and ``write_shard`` stores a whole shard's rows, as zarr would."""

    def __init__(self, arr: zarr.Array, root: Path, codec: ShardingCodec, packer: BloscCodec) -> None:
        meta = arr.metadata
        self.path = root / arr.path
        self.shape = tuple(int(s) for s in meta.shape)
        self.inner = int(codec.chunk_shape[0])
        self.per_shard = int(meta.chunk_grid.chunk_shape[0]) // self.inner  # type: ignore[attr-defined]
        self.dtype = np.dtype(arr.dtype).newbyteorder("<")
        self.fill = np.array(meta.fill_value, dtype=self.dtype)
        first = codec.codecs[0]
        self.order = tuple(first.order) if isinstance(first, TransposeCodec) else None
        # gps_time's fixed scale/offset (siteline.tiles.codecs): numcodecs' own arithmetic both ways
        self.filter = (
            numcodecs.get_codec(dict(first.codec_config)) if isinstance(first, FixedScaleOffset) else None
        )
        stored = self.filter.astype if self.filter is not None else self.dtype
        self.stored = np.dtype(stored).newbyteorder("<")
        self.blosc = (
            packer.cname.value.encode(), packer.clevel, _SHUFFLE[packer.shuffle.value], packer.blocksize,
            packer.typesize,
        )  # fmt: skip
        self.key = meta.encode_chunk_key
        self._index: dict[int, np.ndarray] = {}
        self._lock = threading.Lock()

    def _file(self, s: int) -> Path:
        return self.path / self.key((s,) + (0,) * (len(self.shape) - 1))

    def _shard(self, s: int) -> tuple[Path, np.ndarray | None]:
        """Shard ``s``'s file and its index ((per_shard, 2) uint64 offset and length; None when the
        shard was never written)."""
        path = self._file(s)
        with self._lock:
            found = self._index.get(s)
        if found is not None:
            return path, found
        size = 16 * self.per_shard
        try:
            with open(path, "rb") as f:
                f.seek(-(size + 4), os.SEEK_END)
                raw = f.read(size + 4)
        except FileNotFoundError:
            return path, None
        except OSError as exc:
            raise TileError(f"{path}: cannot read the shard's index ({exc}).") from exc
        if len(raw) != size + 4 or google_crc32c.value(raw[:size]) != int.from_bytes(raw[size:], "little"):
            raise TileError(f"{path}: the shard's index fails its checksum; re-run `siteline scene tile`.")
        index = np.frombuffer(raw[:size], "<u8").reshape(self.per_shard, 2)
        with self._lock:
            self._index[s] = index
        return path, index

    def read(self, i: int) -> np.ndarray:
        rows = min(self.inner, self.shape[0] - i * self.inner)
        path, index = self._shard(i // self.per_shard)
        tail = self.shape[1:]
        if index is None or index[i % self.per_shard, 0] == EMPTY:
            return np.full((rows, *tail), self.fill, dtype=self.dtype)
        offset, length = (int(v) for v in index[i % self.per_shard])
        with open(path, "rb") as f:
            data = os.pread(f.fileno(), length, offset)
        if len(data) != length:
            raise TileError(f"{path}: inner chunk {i} is cut short ({len(data)} of {length} bytes).")
        full = (self.inner, *tail)
        stored = full if self.order is None else tuple(full[k] for k in self.order)
        values = np.frombuffer(blosc.decompress(data), self.stored).reshape(stored)
        if self.order is not None:
            values = values.transpose(np.argsort(self.order))
        if self.filter is not None:
            values = np.asarray(self.filter.decode(values), dtype=self.dtype).reshape(stored)
        return np.ascontiguousarray(values[:rows])

    def _encode(self, rows: np.ndarray) -> bytes:
        """One inner chunk's bytes: ``rows`` (at most ``inner``) padded with the fill value to a whole
        chunk, [transposed or scaled], little-endian, blosc-compressed."""
        if len(rows) < self.inner:
            rows = np.concatenate([rows, np.full((self.inner - len(rows), *rows.shape[1:]), self.fill)])
        values = np.asarray(rows, dtype=self.dtype)
        if self.order is not None:
            values = values.transpose(self.order)
        if self.filter is not None:
            values = np.asarray(self.filter.encode(values))
        cname, clevel, shuffle, blocksize, typesize = self.blosc
        data = np.ascontiguousarray(values, self.stored)
        return bytes(blosc.compress(data, cname, clevel, shuffle, blocksize, typesize))

    def write_shard(self, s: int, values: np.ndarray) -> None:
        """Store shard ``s`` whole: ``values`` are its rows (the shard's length; the last shard's cut
        at the array's end), in its file (replaced), its chunks in order, the index and its crc32c at
        the end; inner chunks wholly past the array's end are left unwritten, as zarr leaves them."""
        start = s * self.per_shard * self.inner
        rows = min(self.per_shard * self.inner, self.shape[0] - start)
        if values.shape != (rows, *self.shape[1:]):
            raise TileError(f"{self._file(s)}: shard {s} takes {rows} rows, not {values.shape[0]}.")
        index = np.full((self.per_shard, 2), EMPTY, dtype="<u8")
        parts, at = [], 0
        for j in range(-(-rows // self.inner)):
            data = self._encode(values[j * self.inner : (j + 1) * self.inner])
            index[j] = (at, len(data))
            parts.append(data)
            at += len(data)
        raw = index.tobytes()
        parts += [raw, google_crc32c.value(raw).to_bytes(4, "little")]
        path = self._file(s)
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "wb") as f:
            f.write(b"".join(parts))
        with self._lock:
            self._index.pop(s, None)


def direct_chunks(arr: zarr.Array) -> DirectChunks | None:
    """A direct reader and writer of ``arr``'s inner chunks when it is laid out as siteline writes it
    and lies on a local disk; None otherwise (zarr reads and writes it)."""
    meta = arr.metadata
    store = arr.store
    if not isinstance(store, LocalStore) or getattr(meta, "zarr_format", None) != 3:
        return None
    codecs = list(getattr(meta, "codecs", ()))
    if len(codecs) != 1 or not isinstance(codecs[0], ShardingCodec):
        return None
    codec = codecs[0]
    inner = list(codec.codecs)
    if inner and isinstance(inner[0], FixedScaleOffset):
        if np.dtype(str(inner[0].codec_config.get("dtype", ""))) != np.dtype(arr.dtype):
            return None
        inner = inner[1:]
    elif inner and isinstance(inner[0], TransposeCodec):
        inner = inner[1:]
    index_ok = [type(c) for c in codec.index_codecs] == [BytesCodec, Crc32cCodec]
    layout_ok = (
        len(inner) == 2
        and isinstance(inner[0], BytesCodec)
        and isinstance(inner[1], BloscCodec)
        and codec.index_location == ShardingCodecIndexLocation.end
        and index_ok
        and len(meta.chunk_grid.chunk_shape) == len(meta.shape)  # type: ignore[attr-defined]
        and all(
            int(s) == int(c)
            for s, c in zip(meta.shape[1:], meta.chunk_grid.chunk_shape[1:], strict=True)  # type: ignore[attr-defined]
        )
        and int(meta.chunk_grid.chunk_shape[0]) % int(codec.chunk_shape[0]) == 0  # type: ignore[attr-defined]
        and tuple(codec.chunk_shape[1:]) == tuple(meta.shape[1:])
    )
    if not layout_ok or np.dtype(arr.dtype).byteorder == ">":
        return None
    return DirectChunks(arr, Path(store.root), codec, cast(BloscCodec, inner[1]))


def read_chunks(tasks: Sequence[tuple[DirectChunks, int]]) -> list[np.ndarray]:
    """Each ``(array, chunk)`` of ``tasks`` decoded, in order, several at once."""
    if len(tasks) == 1:
        return [tasks[0][0].read(tasks[0][1])]
    return list(_pool().map(lambda t: t[0].read(t[1]), tasks))
