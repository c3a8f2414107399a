"""Reading LAS/LAZ files into site-local arrays, streamed in chunks (laspy + lazrs).

Coordinates go from the file's integer counts to float64 CRS metres (laspy's scale and offset) and
then to site-local by float64 subtraction of the site origin, chunk by chunk; only then to float32.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from datetime import date
from pathlib import Path
from typing import Any

import laspy
import numpy as np

from siteline.errors import PointCloudError
from siteline.pointpass.kernels import cut

DEFAULT_CHUNK_POINTS = 1_000_000
# LAS coordinate scales siteline accepts (metres per count): finer collapses a cloud into a few
# millimetres of int32 range, coarser than a metre is not a survey
MIN_SCALE = 1e-7
MAX_SCALE = 1.0
# Beyond this, float32 site-local coordinates lose millimetres: the origin is wrong or missing.
MAX_SITE_LOCAL_M = 20_000.0
# the largest LAZ chunk siteline decodes (points): laszip writes 50,000, and a decoder allocates a whole
# chunk, so a forged chunk size of 2^32 would ask for gigabytes before a point is read
MAX_LAZ_CHUNK_POINTS = 5_000_000
# no LAZ point compresses below this many bytes (a header count beyond file bytes / this is forged)
MIN_LAZ_BYTES_PER_POINT = 1 / 16
# decoding a LAZ chunk past its points may give one point more before its bytes run out (the
# arithmetic decoder reads ahead): a last chunk that decodes this many more than its header count
# leaves it holds more points (measured on six real files: one decodes one point past, none two)
LAZ_OVERRUN_POINTS = 2


@dataclass
class PointChunk:
    """One chunk of points. xyz_crs: (N, 3) float64 georeferenced (CRS units). rgb: (N, 3) uint8 or
    None. classification: (N,) uint8 source codes. intensity: (N,) uint16. gps_time: (N,) float64 or
    None. return_number: (N,) uint8."""

    xyz_crs: np.ndarray
    rgb: np.ndarray | None
    classification: np.ndarray
    intensity: np.ndarray
    gps_time: np.ndarray | None
    return_number: np.ndarray
    colour_8bit: bool | None = None


def open_las(path: Path) -> laspy.LasReader:
    """Open a LAS/LAZ file for streaming; :class:`PointCloudError` naming the file when it is unreadable."""
    path = Path(path)
    if not path.is_file():
        raise PointCloudError(f"point cloud {path} does not exist.")
    try:
        reader = laspy.open(path)
    except (laspy.LaspyException, OSError, ValueError) as exc:
        raise PointCloudError(f"point cloud {path} is not a readable LAS/LAZ file: {exc}") from exc
    try:
        check_header(reader.header, path)
    except BaseException:
        reader.close()
        raise
    return reader


def check_header(header: laspy.LasHeader, path: Path) -> None:
    """Refuse a header that would silently lose or move points: a scale that is not positive or
    outside [MIN_SCALE, MAX_SCALE] per axis, a non-finite offset, or (uncompressed files) a point count
    other than what the file's point data holds."""
    scale = [float(v) for v in header.scales]
    offset = [float(v) for v in header.offsets]
    if not all(np.isfinite(scale)) or not all(np.isfinite(offset)):
        raise PointCloudError(f"point cloud {path}: header scale {scale} / offset {offset} is not finite.")
    bad = [v for v in scale if not MIN_SCALE <= v <= MAX_SCALE]
    if bad:
        raise PointCloudError(
            f"point cloud {path}: header scale {scale} is out of range (each axis from {MIN_SCALE:g} to "
            f"{MAX_SCALE:g} m per count, positive): {bad[0]:g} would collapse, mirror or coarsen the cloud."
        )
    if header.are_points_compressed:
        check_laz_count(header, path)
        return
    size = Path(path).stat().st_size
    end = int(getattr(header, "start_of_first_evlr", 0) or 0) or size
    holds = (end - int(header.offset_to_point_data)) // int(header.point_format.size)
    if holds != header.point_count:
        raise PointCloudError(
            f"point cloud {path}: its header counts {header.point_count:,} points but the file holds {holds:,}: "
            + ("the header is wrong (the rest would be dropped silently); rewrite the file with a LAS tool."
               if holds > header.point_count else "the file is truncated (or its header forged).")
        )  # fmt: skip


def _laz_vlr(header: laspy.LasHeader, path: Path) -> Any:
    """The file's laszip record (lazrs.LazVlr), its chunk size bounded (:data:`MAX_LAZ_CHUNK_POINTS`)."""
    import lazrs

    vlr = next((v for v in header.vlrs if getattr(v, "record_id", None) == 22204), None)
    if vlr is None:
        raise PointCloudError(f"point cloud {path}: a compressed file without its laszip record.")
    try:
        laz = lazrs.LazVlr(vlr.record_data)
    except (lazrs.LazrsError, ValueError) as exc:
        raise PointCloudError(f"point cloud {path}: its laszip record cannot be read ({exc}).") from exc
    if not laz.uses_variable_size_chunks() and not 0 < laz.chunk_size() <= MAX_LAZ_CHUNK_POINTS:
        raise PointCloudError(
            f"point cloud {path}: its laszip record sets chunks of {laz.chunk_size():,} points (at most "
            f"{MAX_LAZ_CHUNK_POINTS:,} are decoded; laszip writes 50,000): the record is forged or corrupt."
        )
    return laz


def laz_chunk_counts(header: laspy.LasHeader, path: Path) -> tuple[list[int], bool]:
    """The point counts of a LAZ file's chunks from its chunk table (lazrs), and whether they are exact:
    a variable-size table records each chunk's count; a fixed-size one (laszip's default, 50,000) says
    only that every chunk but the last is full. :class:`PointCloudError` when there is no table."""
    import lazrs

    laz = _laz_vlr(header, path)
    try:
        with open(path, "rb") as f:
            f.seek(int(header.offset_to_point_data))
            table = lazrs.read_chunk_table(f, laz)
    except (lazrs.LazrsError, OSError, ValueError) as exc:
        raise PointCloudError(f"point cloud {path}: its LAZ chunk table cannot be read ({exc}).") from exc
    if table is None:
        raise PointCloudError(f"point cloud {path}: its LAZ chunk table is missing (a truncated file?).")
    return [int(n) for n, _ in table], bool(laz.uses_variable_size_chunks())


def check_laz_count(header: laspy.LasHeader, path: Path) -> None:
    """Refuse a LAZ whose header point count its chunk table contradicts: more points than its chunks
    can hold (a forged count: nothing is allocated for it), or fewer than its full chunks hold (the
    rest would be dropped silently). A fixed-size table cannot tell a count short by less than its
    last chunk's points (pointwise LAZ does not record that chunk's count); a variable-size one is exact."""
    n = int(header.point_count)
    counts, exact = laz_chunk_counts(header, path)
    low, high = (
        (sum(counts), sum(counts)) if exact else (sum(counts[:-1]) + (1 if counts else 0), sum(counts))
    )
    if not counts and n == 0:
        return
    if not low <= n <= high:
        holds = f"{low:,}" if low == high else f"{low:,} to {high:,}"
        raise PointCloudError(
            f"point cloud {path}: its header counts {n:,} points but its {len(counts)} LAZ chunks hold {holds}: "
            + ("the header is wrong (points past its count would be dropped silently); rewrite the file with "
               "a LAS tool." if n < low else "the header is forged or the file truncated.")
        )  # fmt: skip
    size = Path(path).stat().st_size
    if n > size / MIN_LAZ_BYTES_PER_POINT:
        raise PointCloudError(
            f"point cloud {path}: its header counts {n:,} points, more than its {size:,} bytes can hold: the "
            "header is forged or the file truncated."
        )
    if not exact and counts:
        _check_last_chunk(header, path, n - sum(counts[:-1]))


def _check_last_chunk(header: laspy.LasHeader, path: Path, points: int) -> None:
    """Refuse a LAZ of fixed-size chunks whose last chunk holds more than the ``points`` the header
    count leaves it (its count short by less than a chunk: laszip records no count per chunk, and
    the points past the count would be dropped silently): that chunk's compressed bytes alone still
    decode :data:`LAZ_OVERRUN_POINTS` more points. A count short by one point cannot be told from a
    decoder reading ahead."""
    import io
    import struct

    import lazrs

    laz = _laz_vlr(header, path)
    record = next(v for v in header.vlrs if getattr(v, "record_id", None) == 22204).record_data
    with open(path, "rb") as f:
        f.seek(int(header.offset_to_point_data))
        table = lazrs.read_chunk_table(f, laz) or []
        if not table:
            return
        start = int(header.offset_to_point_data) + 8 + sum(int(b) for _, b in table[:-1])
        f.seek(start)
        chunk = f.read(int(table[-1][1]))
    more = points + LAZ_OVERRUN_POINTS
    stream = io.BytesIO()
    stream.write(struct.pack("<q", 8 + len(chunk)))
    stream.write(chunk)
    lazrs.write_chunk_table(stream, [(more, len(chunk))], laz)
    stream.seek(0)
    decoder = lazrs.LasZipDecompressor(stream, record)  # reads the table, then the chunk from its start
    stream.truncate(8 + len(chunk))  # so the decoder runs out where the chunk's bytes end
    try:
        decoder.decompress_many(bytearray(more * int(header.point_format.size)))
    except lazrs.LazrsError:
        return  # the chunk's data ran out where the header says: the count is right
    raise PointCloudError(
        f"point cloud {path}: its header counts {int(header.point_count):,} points but its last LAZ chunk holds "
        f"more than the {points:,} that count leaves it: the header is wrong (the points past its count would be "
        "dropped silently); rewrite the file with a LAS tool."
    )


def iter_chunks(
    path: Path,
    chunk_points: int = DEFAULT_CHUNK_POINTS,
    eight_bit: bool | None = None,
    reader: laspy.LasReader | None = None,
    start: int = 0,
    stop: int | None = None,
) -> Iterator[PointChunk]:
    """Stream a LAS/LAZ file as :class:`PointChunk` s. ``eight_bit`` (colour stored as 0-255 in 16-bit
    fields) is detected from the first chunk when None. ``reader``: the file already opened (by
    :func:`open_las`), so a caller that read its header does not open it twice. ``start``/``stop``:
    the points [start, stop) only (a seek: LAZ decodes from the compressed chunk that holds start)."""
    with contextlib.nullcontext(reader) if reader is not None else open_las(path) as reader:
        has_rgb = "red" in reader.header.point_format.dimension_names
        has_time = "gps_time" in reader.header.point_format.dimension_names
        scale = np.asarray(reader.header.scales, dtype=np.float64)
        offset = np.asarray(reader.header.offsets, dtype=np.float64)
        try:
            for pts in _point_records(reader, chunk_points, start, stop):
                xyz = cut.scaled_xyz(pts.X, pts.Y, pts.Z, scale, offset)
                rgb = None
                if has_rgb:
                    red, green, blue = np.asarray(pts.red), np.asarray(pts.green), np.asarray(pts.blue)
                    if eight_bit is None:
                        eight_bit = _eight_bit(red, green, blue)
                    rgb = cut.colour_u8(red, green, blue, 0 if eight_bit else 8)
                yield PointChunk(
                    xyz_crs=xyz,
                    rgb=rgb,
                    classification=np.asarray(pts.classification, dtype=np.uint8),
                    intensity=np.asarray(pts.intensity, dtype=np.uint16),
                    gps_time=np.asarray(pts.gps_time, dtype=np.float64) if has_time else None,
                    return_number=np.asarray(pts.return_number, dtype=np.uint8),
                    colour_8bit=eight_bit if has_rgb else None,
                )
        except (laspy.LaspyException, OSError, ValueError, RuntimeError) as exc:
            raise PointCloudError(f"point cloud {path} is truncated or corrupt: {exc}") from exc


def _point_records(
    reader: laspy.LasReader, chunk_points: int, start: int, stop: int | None
) -> Iterator[laspy.ScaleAwarePointRecord]:
    """The reader's points [start, stop) in records of at most ``chunk_points``."""
    if start == 0 and stop is None:
        yield from reader.chunk_iterator(chunk_points)
        return
    end = int(reader.header.point_count) if stop is None else min(stop, int(reader.header.point_count))
    if start:
        reader.seek(start)
    pos = start
    while pos < end:
        pts = reader.read_points(min(chunk_points, end - pos))
        if len(pts) == 0:
            raise PointCloudError(f"the file ends at point {pos:,} of {end:,}")
        pos += len(pts)
        yield pts


def detect_eight_bit(
    reader: laspy.LasReader, path: Path, chunk_points: int = DEFAULT_CHUNK_POINTS
) -> bool | None:
    """Whether the file ``path``'s colour holds 0-255 in 16-bit fields, judged as :func:`iter_chunks`
    does (its first ``chunk_points`` points); None when it has no colour. Leaves the reader at point 0."""
    if "red" not in reader.header.point_format.dimension_names:
        return None
    try:
        pts = reader.read_points(min(chunk_points, int(reader.header.point_count)))
        reader.seek(0)
    except (laspy.LaspyException, OSError, ValueError, RuntimeError) as exc:
        raise PointCloudError(f"point cloud {path} is truncated or corrupt: {exc}") from exc
    return _eight_bit(np.asarray(pts.red), np.asarray(pts.green), np.asarray(pts.blue))


def _eight_bit(*channels: np.ndarray) -> bool:
    """Whether LAS colour channels (uint16) hold only 0-255: 8-bit colour in 16-bit fields."""
    return max(int(c.max(initial=0)) for c in channels) <= 255


def las_offset(xyz_min: np.ndarray, scale: float) -> np.ndarray:
    """A LAS offset near the data: the minimum rounded down to a multiple of 1000 scale units, so
    |coordinate - offset| stays far below 2^31 x scale (DESIGN.md §2)."""
    step = 1000.0 * scale
    return np.floor(np.asarray(xyz_min, dtype=np.float64) / step) * step


def las_header(
    crs_text: str | None,
    xyz_min: np.ndarray,
    scale: float = 0.001,
    point_format: int = 3,
    version: str = "1.2",
    *,
    created: date | None = None,
    software: tuple[str, str] | None = None,
    vlrs: Sequence[laspy.VLR] = (),
) -> laspy.LasHeader:
    """A LAS header with ``scale`` on every axis, an offset near ``xyz_min``, the CRS record, and
    optionally a creation date, (system identifier, generating software) and extra VLRs."""
    import pyproj

    header = laspy.LasHeader(point_format=point_format, version=version)
    header.scales = np.array([scale, scale, scale])
    header.offsets = las_offset(xyz_min, scale)
    if crs_text:
        header.add_crs(pyproj.CRS.from_user_input(crs_text))
    if created is not None:
        header.creation_date = created
    if software is not None:
        header.system_identifier, header.generating_software = software
    header.vlrs.extend(vlrs)
    return header


# what fill_record sets
FIELDS = ("rgb", "classification", "intensity", "gps_time", "return_number", "number_of_returns")


def fill_record(record: laspy.ScaleAwarePointRecord, xyz_crs: np.ndarray, fields: Mapping[str, Any]) -> None:
    """Set a point record's fields from float64 georeferenced coordinates and ``fields`` (any of
    :data:`FIELDS`, None or absent: left zero). Colour (N, 3) 0-255 is written as 16-bit (value *
    257), as LAS expects; ``number_of_returns`` absent: at least the return number (never 0)."""
    unknown = set(fields) - set(FIELDS)
    if unknown:
        raise PointCloudError(
            f"fields {sorted(unknown)} are not LAS fields siteline writes ({', '.join(FIELDS)})."
        )
    record.x = xyz_crs[:, 0]
    record.y = xyz_crs[:, 1]
    record.z = xyz_crs[:, 2]
    rgb, return_number = fields.get("rgb"), fields.get("return_number")
    if rgb is not None:
        rgb16 = np.asarray(rgb).astype(np.uint16) * 257
        record.red, record.green, record.blue = rgb16[:, 0], rgb16[:, 1], rgb16[:, 2]
    for name in ("classification", "intensity", "gps_time", "number_of_returns"):
        if fields.get(name) is not None:
            setattr(record, name, fields[name])
    if return_number is not None:
        record.return_number = return_number
        if fields.get("number_of_returns") is None:
            record.number_of_returns = np.maximum(return_number, 1)


class LasWriter:
    """A LAS/LAZ file (by extension) written chunk by chunk under ``header``
    (:func:`las_header`): each chunk is float64 georeferenced coordinates and :data:`FIELDS`."""

    def __init__(self, path: Path, header: laspy.LasHeader) -> None:
        self.header = header
        self._writer = laspy.open(path, mode="w", header=header)

    def write(self, xyz_crs: np.ndarray, **fields: np.ndarray | None) -> None:
        """Append ``len(xyz_crs)`` points."""
        record = laspy.ScaleAwarePointRecord.zeros(len(xyz_crs), header=self.header)
        fill_record(record, np.asarray(xyz_crs, dtype=np.float64), fields)
        self._writer.write_points(record)

    def __enter__(self) -> LasWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self._writer.close()


def write_las(
    path: Path, xyz_crs: np.ndarray, *, crs: str | None, scale: float = 0.001, **fields: np.ndarray | None
) -> None:
    """Write a small LAS/LAZ file (by extension) in one go; point format 3, version 1.2; ``fields``:
    per-point arrays named as in :data:`FIELDS` (rgb, classification, intensity, gps_time,
    return_number)."""
    xyz = np.asarray(xyz_crs, dtype=np.float64)
    header = las_header(crs, xyz.min(axis=0) if len(xyz) else np.zeros(3), scale)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with LasWriter(path, header) as writer:
        writer.write(xyz, **fields)


def write_changed_classes(first: Path, second: Path, out: Path, chunk: int = 1_000_000) -> int:
    """Write to ``out`` (under ``second``'s header) the points of ``second`` whose classification
    differs from the same point of ``first`` (two files of the same points in the same order, read in
    step ``chunk`` points at a time); return how many."""
    n = 0
    with laspy.open(first) as a, laspy.open(second) as b, laspy.open(out, mode="w", header=b.header) as w:
        for pa, pb in zip(a.chunk_iterator(chunk), b.chunk_iterator(chunk), strict=True):
            changed = np.asarray(pa.classification) != np.asarray(pb.classification)
            if changed.any():
                w.write_points(pb[changed])
                n += int(changed.sum())
    return n


@dataclass(frozen=True)
class LasHeaderFacts:
    """What a scan records of a file's header: LAS version ("1.4"), point format id, scales and
    offsets (per axis), creation date, whether GPS times are standard (adjusted) GPS time, and who
    wrote the file (the header's system identifier and generating software, "; "-joined; None when
    both are blank)."""

    version: str
    point_format: int
    scales: list[float]
    offsets: list[float]
    creation_date: date | None
    gps_time_standard: bool
    software: str | None = None


def header_facts(header: laspy.LasHeader) -> LasHeaderFacts:
    """The :class:`LasHeaderFacts` of a header."""
    return LasHeaderFacts(
        f"{header.version.major}.{header.version.minor}", int(header.point_format.id),
        [float(v) for v in header.scales], [float(v) for v in header.offsets], header.creation_date,
        bool(int(header.global_encoding.gps_time_type)),
        "; ".join(t for t in (str(v).strip("\x00 ") for v in (header.system_identifier, header.generating_software)) if t) or None,
    )  # fmt: skip


LABELS_VLR_USER = "siteline"
LABELS_VLR_RECORD = 1


def labels_vlr(doc: dict) -> laspy.VLR:
    """A VLR carrying what a file's classification means (site, scene, label-set version, taxonomy)
    as JSON, so a file corrected elsewhere can be checked when it comes back."""
    import json

    return laspy.VLR(
        user_id=LABELS_VLR_USER,
        record_id=LABELS_VLR_RECORD,
        description="siteline label set",
        record_data=json.dumps(doc, sort_keys=True).encode(),
    )


def read_labels_vlr(header: laspy.LasHeader, path: Path) -> dict | None:
    """The document of :func:`labels_vlr` in a header, None when the file has none (an editor may
    drop VLRs); :class:`PointCloudError` when it is there but unreadable."""
    import json

    for vlr in [*header.vlrs, *(getattr(header, "evlrs", None) or [])]:
        if vlr.user_id == LABELS_VLR_USER and vlr.record_id == LABELS_VLR_RECORD:
            try:
                return json.loads(bytes(vlr.record_data).decode())
            except (UnicodeDecodeError, ValueError) as exc:
                raise PointCloudError(
                    f"point cloud {path}: its siteline label-set record is corrupt ({exc})."
                ) from exc
    return None
