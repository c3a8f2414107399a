"""How tile arrays are compressed (zarr v3 codecs): the one place to choose a codec per attribute.
Today every array takes blosc-zstd with byte shuffle at ``TileSpec.clevel``; bench/ingest.py reports
the bytes per point it gives against the source LAZ."""

from __future__ import annotations

from typing import Any

import numpy as np
from zarr.codecs import BloscCodec, BloscShuffle

from siteline.records.tiling import TileSpec


def array_codecs(name: str, dtype: np.dtype, spec: TileSpec) -> dict[str, Any]:
    """``create_array`` keyword arguments (compressors) for tile array ``name`` of ``dtype``."""
    return {"compressors": BloscCodec(cname="zstd", clevel=spec.clevel, shuffle=BloscShuffle.shuffle)}
