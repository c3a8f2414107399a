"""The Hugging Face ``datasets`` export (``--profile hf``): a release as parquet shards and a dataset
card that ``datasets.load_dataset(FOLDER)`` reads with no code of ours.

Each row is one item: its four images as the PNG bytes of the release (``image_a``, ``image_b``;
``label`` 0 unchanged, 1 changed, 255 ignore, from ``label_ignore/``; ``ignore`` 255 where ignored),
its split, pair, view, figures and camera. Shards are ``data/<split>-NNNNN-of-NNNNN.parquet``, cut at
:data:`SHARD_BYTES` of images, written with the features in the parquet schema (key ``huggingface``)
and in the card's YAML header (``configs`` maps the hub's splits to the shard files). The hub names the
release's ``val`` split ``validation``. Needs the ``datasets`` package (``pip install 'siteline[hf]'``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from siteline.codes import IGNORE_CAUSES
from siteline.errors import ReleaseError
from siteline.schema import JsonObject

HUB_SPLITS = {"train": "train", "val": "validation", "test": "test"}
SHARD_BYTES = 256 * 2**20  # images per shard, bytes: the hub's viewer and streaming like 100-500 MB files
ROW_GROUP_ROWS = 64  # rows per parquet row group: images are large, readers fetch a group at a time
IMAGE_FOLDERS = {"image_a": "A", "image_b": "B", "label": "label_ignore", "ignore": "ignore"}
CITATION = """@inproceedings{mao2026ivision2dcd,
  title     = {iVISION-2DCD: A Long-Term Change Detection Dataset for Large-Scale Outdoor Construction Monitoring},
  author    = {Mao, Dayou and Lin, Yuchen and Ebadi, Ashkan and Zelek, John and Wong, Alexander and Chen, Yuhao},
  booktitle = {IEEE International Conference on Robotics and Automation (ICRA)},
  year      = {2026}
}"""


def _datasets() -> Any:
    try:
        import datasets
    except ImportError as exc:
        raise ReleaseError(
            "the hf export profile needs the datasets package: pip install 'siteline[hf]' (datasets>=4)."
        ) from exc
    return datasets


def features() -> Any:
    """The ``datasets.Features`` of a row (images decode to PIL images; figures are shares in [0, 1];
    camera as ``schema/camera.schema.json``, site-local metres, null where the release recorded none)."""
    ds = _datasets()
    f64, i32 = ds.Value("float64"), ds.Value("int32")
    return ds.Features(
        {
            "id": ds.Value("string"),
            **{name: ds.Image() for name in IMAGE_FOLDERS},
            "split": ds.Value("string"),
            "pair": i32,
            "view": i32,
            "strategy": ds.Value("string"),
            "coverage": f64,
            "valid": f64,
            "change_ratio": f64,
            "filled": f64,
            "width": i32,
            "height": i32,
            "ignore_causes": {cause: f64 for cause in IGNORE_CAUSES},
            "camera": {
                **{k: f64 for k in ("fx", "fy", "cx", "cy")},
                "rotation": ds.List(ds.List(f64)),
                "translation": ds.List(f64),
            },
        }
    )


def _row(root: Path, it: JsonObject) -> JsonObject:
    images = {}
    for name, folder in IMAGE_FOLDERS.items():
        path = root / it["split"] / folder / f"{it['id']}.png"
        if not path.is_file():
            raise ReleaseError(f"{path} is missing: the release is incomplete (`siteline release verify`).")
        images[name] = {"bytes": path.read_bytes(), "path": f"{it['id']}.png"}
    cam = it.get("camera")
    return {
        "id": it["id"], **images, "split": it["split"], "pair": it["pair"], "view": it["view"],
        "strategy": it["strategy"], "coverage": it["coverage"], "valid": it["valid"],
        "change_ratio": it["change_ratio"], "filled": it.get("filled", 0.0),
        "width": it["size_px"][0], "height": it["size_px"][1],
        "ignore_causes": {c: float(it.get("ignore", {}).get(c, 0.0)) for c in IGNORE_CAUSES} if it.get("ignore") else None,
        "camera": {k: cam[k] for k in ("fx", "fy", "cx", "cy")} | cam["cam_from_world"] if cam else None,
    }  # fmt: skip


def _shards(root: Path, items: list[JsonObject]) -> list[list[JsonObject]]:
    """Items cut into shards of at most SHARD_BYTES of images (at least one item each)."""
    shards: list[list[JsonObject]] = []
    size = SHARD_BYTES
    for it in items:
        item_bytes = sum((root / it["split"] / f / f"{it['id']}.png").stat().st_size for f in IMAGE_FOLDERS.values())
        if size + item_bytes > SHARD_BYTES and (not shards or shards[-1]):
            shards.append([])
            size = 0
        shards[-1].append(it)
        size += item_bytes
    return shards


def size_category(n: int) -> str:
    """The hub's ``size_categories`` value for ``n`` rows."""
    for limit, name in ((1_000, "n<1K"), (10_000, "1K<n<10K"), (100_000, "10K<n<100K"), (1_000_000, "100K<n<1M")):
        if n < limit:
            return name
    return "1M<n<10M"


@dataclass(frozen=True)
class Shards:
    """What an export wrote: hub split -> shard paths (relative to the export), rows, and bytes as
    arrow tables (the card's ``num_bytes``) and as parquet files (``download_size``)."""

    files: dict[str, list[str]]
    rows: dict[str, int]
    num_bytes: dict[str, int]
    file_bytes: int


def write_shards(root: Path, doc: JsonObject, work: Path) -> Shards:
    """The parquet shards of every split in ``work/data/``."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    feats = features()
    schema = feats.arrow_schema
    written: dict[str, list[str]] = {}
    rows: dict[str, int] = {}
    num_bytes: dict[str, int] = {}
    (work / "data").mkdir(parents=True)
    for split, hub in HUB_SPLITS.items():
        items = sorted((it for it in doc["items"] if it["split"] == split), key=lambda it: it["id"])
        shards = _shards(root, items)
        for n, shard in enumerate(shards):
            rel = f"data/{hub}-{n:05d}-of-{len(shards):05d}.parquet"
            table = pa.Table.from_pylist([feats.encode_example(_row(root, it)) for it in shard], schema=schema)
            pq.write_table(table, work / rel, row_group_size=ROW_GROUP_ROWS)
            written.setdefault(hub, []).append(rel)
            rows[hub] = rows.get(hub, 0) + table.num_rows
            num_bytes[hub] = num_bytes.get(hub, 0) + table.nbytes
    file_bytes = sum((work / rel).stat().st_size for rels in written.values() for rel in rels)
    return Shards(written, rows, num_bytes, file_bytes)


def card(doc: JsonObject, shards: Shards, license_id: str, datasheet: str) -> str:
    """README.md of the export: the hub's YAML header (licence, task, sizes, splits and their files,
    features), how to load it, what the fields hold, the citation, then the release's own datasheet."""
    from huggingface_hub import DatasetCardData

    counts = shards.rows
    data = DatasetCardData(
        license=license_id,
        pretty_name=f"{doc['name']} {doc['version']} (siteline change detection)",
        task_categories=["image-segmentation"],
        task_ids=["semantic-segmentation"],
        size_categories=[size_category(len(doc["items"]))],
        tags=["change-detection", "construction", "drone", "lidar", "siteline"],
        configs=[
            {"config_name": "default", "data_files": [{"split": s, "path": f"data/{s}-*.parquet"} for s in counts]}
        ],
        dataset_info={
            "features": features()._to_yaml_list(),
            "splits": [{"name": s, "num_bytes": shards.num_bytes[s], "num_examples": n} for s, n in counts.items()],
            "download_size": shards.file_bytes,
            "dataset_size": sum(shards.num_bytes.values()),
        },
    )
    sizes = ", ".join(f"{s} {n}" for s, n in counts.items())
    body = [
        f"# {doc['name']} {doc['version']}",
        "",
        f"A bi-temporal change-detection dataset made by siteline from drone LiDAR scenes of a construction site "
        f"(the iVISION-2DCD method): {len(doc['items'])} pixel-aligned image pairs ({sizes}) with symmetric change "
        "masks, exported from the immutable release as parquet shards.",
        "",
        "```python",
        "from datasets import load_dataset",
        'ds = load_dataset("path/to/this/folder")  # or the hub id once pushed',
        'item = ds["train"][0]  # item["image_a"], item["image_b"], item["label"]: PIL images',
        "```",
        "",
        "| field | holds |",
        "|---|---|",
        "| `image_a`, `image_b` | t1 and t2 renders (RGB, 8-bit), pixel-aligned; padded right and bottom to a multiple of 32 px |",
        "| `label` | 0 unchanged, 1 changed, 255 ignore (train with `ignore_index=255`) |",
        "| `ignore` | 255 where the pixel is ignored (no surface, a gap, seen from one side, outside the fence, an "
        "ignored class, padding), else 0 |",
        "| `split` | the release's split (`val` is the hub's `validation`) |",
        "| `pair`, `view` | the pair of consecutive scenes and the synthetic view's index in it |",
        "| `strategy` | how the view was derived from a real camera (tilt, mirror, forward shift) |",
        "| `coverage`, `valid`, `change_ratio`, `filled` | shares of the rendered image: covered in both epochs, "
        "labelled, changed, and filled across gaps |",
        "| `width`, `height` | the rendered size inside the padded image, pixels |",
        "| `ignore_causes` | share of the rendered image ignored for each cause |",
        "| `camera` | the synthetic camera: fx, fy, cx, cy (pixels), `x_cam = rotation x_site + translation` (site-local metres) |",
        "",
        "## Citation",
        "",
        "```bibtex",
        CITATION,
        "```",
        "",
        "## Datasheet (the release's README)",
        "",
        datasheet,
    ]  # fmt: skip
    return f"---\n{data.to_yaml()}\n---\n\n" + "\n".join(body) + "\n"


def export_hf(root: Path, doc: JsonObject, work: Path, license_id: str) -> Shards:
    """Write the hub export of the release at ``root`` (manifest ``doc``) into the new folder ``work``:
    parquet shards and README.md (the release's montage copied beside it)."""
    shards = write_shards(root, doc, work)
    datasheet = (root / "README.md").read_text() if (root / "README.md").is_file() else ""
    if (root / "montage.png").is_file():
        (work / "montage.png").write_bytes((root / "montage.png").read_bytes())
    (work / "README.md").write_text(card(doc, shards, license_id, datasheet))
    return shards
