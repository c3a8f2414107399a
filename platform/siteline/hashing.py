"""Content hashes (sha256): the one place files are hashed, for mission manifests, blobs and
release checksums."""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from pathlib import Path

HASH_BLOCK_BYTES = 4 * 2**20


def sha256_file(path: Path, progress: Callable[[int], None] | None = None) -> str:
    """Hex sha256 of the file at ``path``, read in blocks; ``progress`` receives bytes read."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(HASH_BLOCK_BYTES):
            h.update(block)
            if progress:
                progress(len(block))
    return h.hexdigest()
