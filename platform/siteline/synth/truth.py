"""Ground-truth sidecar files: ``.npy`` arrays appended chunk by chunk (memory does not grow)."""

from __future__ import annotations

import ast
from pathlib import Path
from types import TracebackType

import numpy as np
import numpy.typing as npt

_HEADER_LEN = 128  # bytes, magic included: room for any shape a synthetic epoch reaches


class NpyAppender:
    """Write a 1-D ``.npy`` array in pieces: a fixed-size header is rewritten with the final length."""

    def __init__(self, path: Path, dtype: npt.DTypeLike) -> None:
        self.path = Path(path)
        self.dtype = np.dtype(dtype)
        self.count = 0
        self._fh = open(self.path, "wb")
        self._fh.write(self._header(0))

    def _header(self, n: int) -> bytes:
        d = {"descr": np.lib.format.dtype_to_descr(self.dtype), "fortran_order": False, "shape": (n,)}
        text = repr(d).encode("latin1")
        pad = _HEADER_LEN - 10 - len(text) - 1
        return b"\x93NUMPY\x01\x00" + (_HEADER_LEN - 10).to_bytes(2, "little") + text + b" " * pad + b"\n"

    def append(self, values: np.ndarray) -> None:
        arr = np.ascontiguousarray(values, dtype=self.dtype)
        self._fh.write(arr.tobytes())
        self.count += len(arr)

    def close(self) -> None:
        if self._fh.closed:
            return
        self._fh.seek(0)
        self._fh.write(self._header(self.count))
        self._fh.close()

    def __enter__(self) -> NpyAppender:
        return self

    def __exit__(self, t: type | None, v: BaseException | None, tb: TracebackType | None) -> None:
        self.close()


def header_shape(path: Path) -> tuple[int, ...]:
    """Shape recorded in a ``.npy`` header (for checks without loading the data)."""
    with open(path, "rb") as fh:
        fh.read(8)
        n = int.from_bytes(fh.read(2), "little")
        return tuple(ast.literal_eval(fh.read(n).decode("latin1"))["shape"])
