"""How tile arrays are compressed (zarr v3 codecs): the one place to choose a codec per attribute.

Every array takes blosc-zstd at ``TileSpec.clevel`` with bit shuffle: inside a level of a node the
points are sorted by the low bits of their counts (``node_order="reversed-morton"``), so those bit
planes come in runs, and a chunk's high bits barely change (no delta codec helps: neighbours in the
arrays are not neighbours in space). Two filters
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
from typing import Any, TypedDict

import numpy as np
from zarr.codecs import BloscCodec, BloscShuffle, TransposeCodec
from zarr.errors import ZarrUserWarning

from siteline.records.tiling import TileSpec

# zarr warns on every numcodecs codec it builds, reading included; the one siteline uses
# (fixedscaleoffset) is read by zarr-python >= 3.1.3, the range siteline requires
warnings.filterwarnings("ignore", message="Numcodecs codecs are not in the Zarr", category=ZarrUserWarning)

TIME_SCALES = tuple(10.0**k for k in range(10))  # seconds to ns
_PROBE = 4096


def round_trips(values: np.ndarray, scale: float) -> bool:
    """Whether every float64 of ``values`` survives the fixed scale/offset codec at ``scale``."""
    from numcodecs import FixedScaleOffset

    values = np.ascontiguousarray(values, dtype=np.float64).ravel()
    if not np.isfinite(values).all() or float(np.abs(values).max(initial=0.0)) * scale >= 2.0**62:
        return False
    codec = FixedScaleOffset(offset=0, scale=scale, dtype="<f8", astype="<i8")
    return bool(np.array_equal(codec.decode(codec.encode(values)), values))


def time_scale(values: np.ndarray) -> float | None:
    """The coarsest of :data:`TIME_SCALES` at which every float64 of ``values`` survives the fixed
    scale/offset codec (offset 0) bit for bit; None when none does (or a value is not finite)."""
    values = np.ascontiguousarray(values, dtype=np.float64).ravel()
    if not np.isfinite(values).all():
        return None
    probe = values[:: max(1, len(values) // _PROBE)]
    return next((s for s in TIME_SCALES if round_trips(probe, s) and round_trips(values, s)), None)


class ArrayCodecs(TypedDict, total=False):
    """``create_array``'s codec keyword arguments for one tile array (absent: zarr's default)."""

    compressors: BloscCodec
    filters: list[Any]


def array_codecs(name: str, dtype: np.dtype, ndim: int, spec: TileSpec, scale: float | None) -> ArrayCodecs:
    """``create_array`` keyword arguments (filters, compressors) for tile array ``name`` of ``dtype``
    and ``ndim`` dimensions; ``scale``: the gps_time scale (:func:`time_scale` of all its values)."""
    from zarr.codecs.numcodecs import FixedScaleOffset

    out: ArrayCodecs = {
        "compressors": BloscCodec(cname="zstd", clevel=spec.clevel, shuffle=BloscShuffle.bitshuffle)
    }
    if ndim == 2:
        out["filters"] = [TransposeCodec(order=(1, 0))]
    elif name == "gps_time" and dtype == np.float64 and scale is not None:
        out["filters"] = [FixedScaleOffset(offset=0, scale=scale, dtype="<f8", astype="<i8")]
    return out
