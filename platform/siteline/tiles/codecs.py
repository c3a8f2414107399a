"""How tile arrays are compressed (zarr v3 codecs): the one place to choose a codec per attribute.

Every array takes blosc-zstd at ``TileSpec.clevel`` with bit shuffle (inside a node the points are
shuffled, so no delta codec helps; bit planes do: a chunk's high bits barely change). Two filters
narrow what blosc sees, both lossless and both decoded by zarr itself, so a reader gets the stored
dtype back:

- ``xyz_counts`` (N, 3) int32 is transposed to planar x, y, z inside each chunk (zarr's transpose
  codec), so each coordinate's bit planes are contiguous: 5.4 -> 4.8 bytes a point on the bench site;
- ``gps_time`` float64 is stored as int64 multiples of the coarsest power-of-ten second (1 s .. 1 ns)
  at which every value of the array round-trips bit for bit (numcodecs' fixed scale/offset codec,
  checked with that codec's own arithmetic before it is chosen): microsecond times 4.3 -> 2.4 bytes a
  point. An array that round-trips at no scale stays float64.

bench/ingest.py reports the bytes per point against the source LAZ.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
from zarr.codecs import BloscCodec, BloscShuffle, TransposeCodec
from zarr.errors import ZarrUserWarning

from siteline.records.tiling import TileSpec

# zarr warns on every numcodecs codec it builds, reading included; the one siteline uses
# (fixedscaleoffset) is read by zarr-python >= 3.1.3, the range siteline requires
warnings.filterwarnings("ignore", message="Numcodecs codecs are not in the Zarr", category=ZarrUserWarning)

TIME_SCALES = tuple(10.0**k for k in range(10))  # seconds to ns
_PROBE = 4096


def time_scale(values: np.ndarray) -> float | None:
    """The coarsest of :data:`TIME_SCALES` at which every float64 of ``values`` survives the fixed
    scale/offset codec (offset 0) bit for bit; None when none does (or a value is not finite)."""
    from numcodecs import FixedScaleOffset

    values = np.ascontiguousarray(values, dtype=np.float64).ravel()
    if not len(values):
        return 1.0
    if not np.isfinite(values).all():
        return None
    top = float(np.abs(values).max())
    probe = values[:: max(1, len(values) // _PROBE)]
    for scale in (s for s in TIME_SCALES if top * s < 2.0**62):
        codec = FixedScaleOffset(offset=0, scale=scale, dtype="<f8", astype="<i8")
        if np.array_equal(codec.decode(codec.encode(probe)), probe) and np.array_equal(
            codec.decode(codec.encode(values)), values
        ):
            return scale
    return None


def array_codecs(name: str, values: np.ndarray, spec: TileSpec) -> dict[str, Any]:
    """``create_array`` keyword arguments (filters, compressors) for tile array ``name`` holding
    ``values``."""
    from zarr.codecs.numcodecs import FixedScaleOffset

    out: dict[str, Any] = {
        "compressors": BloscCodec(cname="zstd", clevel=spec.clevel, shuffle=BloscShuffle.bitshuffle)
    }
    if values.ndim == 2:
        out["filters"] = [TransposeCodec(order=(1, 0))]
    elif name == "gps_time" and values.dtype == np.float64:
        scale = time_scale(values)
        if scale is not None:
            out["filters"] = [FixedScaleOffset(offset=0, scale=scale, dtype="<f8", astype="<i8")]
    return out
