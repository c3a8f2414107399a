"""The Hugging Face ``datasets`` export (``--profile hf``): a release as parquet shards and a dataset
card that ``datasets.load_dataset(FOLDER)`` reads with no code of ours.

Each row is one item: its four images as the PNG bytes of the release (``image_a``, ``image_b``;
``label`` 0 unchanged, 1 changed, 255 ignore, from ``label_ignore/``; ``ignore`` 255 where ignored),
``label_preview`` (the mask in colour, for the hub's viewer),
its split, pair, view, figures and camera. Shards are ``data/<split>-NNNNN-of-NNNNN.parquet``, cut at
:data:`SHARD_BYTES` of images, written with the features in the parquet schema (key ``huggingface``)
and in the card's YAML header (``configs`` maps the hub's splits to the shard files). The hub names the
release's ``val`` split ``validation``. Needs the ``datasets`` package (``pip install 'siteline[hf]'``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypedDict

import numpy as np

from siteline.codes import IGNORE_CAUSES, SYNTHETIC_SOFTWARE
from siteline.errors import ReleaseError
from siteline.labels.accuracy import accuracy_text
from siteline.records.pairs import ChangeLabels
from siteline.records.params.pairs import PairParams
from siteline.records.release import Manifest, ReleaseItem, ReleaseStats
from siteline.schema import json_object

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
            "label_preview": ds.Image(),
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


def _row(root: Path, it: ReleaseItem) -> dict[str, object]:
    """The hub row of item ``it``: its images (PNG bytes), figures and camera."""
    images: dict[str, dict[str, object]] = {}
    for name, folder in IMAGE_FOLDERS.items():
        path = root / it.split / folder / f"{it.id}.png"
        if not path.is_file():
            raise ReleaseError(f"{path} is missing: the release is incomplete (`siteline release verify`).")
        images[name] = {"bytes": path.read_bytes(), "path": f"{it.id}.png"}
    images["label_preview"] = {
        "bytes": _preview(root / it.split / "label_ignore" / f"{it.id}.png"),
        "path": f"{it.id}.png",
    }
    cam = it.camera
    return {
        "id": it.id, **images, "split": it.split, "pair": it.pair, "view": it.view,
        "strategy": it.strategy, "coverage": it.coverage, "valid": it.valid,
        "change_ratio": it.change_ratio, "filled": it.filled,
        "width": it.size_px[0], "height": it.size_px[1],
        "ignore_causes": {c: float(it.ignore.get(c, 0.0)) for c in IGNORE_CAUSES} if it.ignore else None,
        "camera": {**{k: cam[k] for k in ("fx", "fy", "cx", "cy")}, **json_object(cam["cam_from_world"])} if cam else None,
    }  # fmt: skip


def _preview(label: Path) -> bytes:
    """The 0/1/255 mask at ``label`` as an RGB PNG in the release's mask colours (the hub's viewer shows
    the raw mask as black)."""
    import io

    from PIL import Image

    from siteline.release.datasheet import colour_mask

    with Image.open(label) as im:
        rgb = colour_mask(np.asarray(im))
    buf = io.BytesIO()
    Image.fromarray(rgb).save(buf, format="PNG", optimize=False)
    return buf.getvalue()


def _shards(root: Path, items: list[ReleaseItem]) -> list[list[ReleaseItem]]:
    """Items cut into shards of at most SHARD_BYTES of images (at least one item each)."""
    shards: list[list[ReleaseItem]] = []
    size = SHARD_BYTES
    for it in items:
        item_bytes = sum(
            (root / it.split / f / f"{it.id}.png").stat().st_size for f in IMAGE_FOLDERS.values()
        )
        if size + item_bytes > SHARD_BYTES and (not shards or shards[-1]):
            shards.append([])
            size = 0
        shards[-1].append(it)
        size += item_bytes
    return shards


def size_category(n: int) -> str:
    """The hub's ``size_categories`` value for ``n`` rows."""
    for limit, name in (
        (1_000, "n<1K"),
        (10_000, "1K<n<10K"),
        (100_000, "10K<n<100K"),
        (1_000_000, "100K<n<1M"),
    ):
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


def write_shards(root: Path, doc: Manifest, work: Path) -> Shards:
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
        items = doc.items_of(split)
        shards = _shards(root, items)
        for n, shard in enumerate(shards):
            rel = f"data/{hub}-{n:05d}-of-{len(shards):05d}.parquet"
            table = pa.Table.from_pylist(
                [feats.encode_example(_row(root, it)) for it in shard], schema=schema
            )
            pq.write_table(table, work / rel, row_group_size=ROW_GROUP_ROWS)
            written.setdefault(hub, []).append(rel)
            rows[hub] = rows.get(hub, 0) + table.num_rows
            num_bytes[hub] = num_bytes.get(hub, 0) + table.nbytes
    file_bytes = sum((work / rel).stat().st_size for rels in written.values() for rel in rels)
    return Shards(written, rows, num_bytes, file_bytes)


class CardLicence(TypedDict, total=False):
    """The licence fields of a hub dataset card (huggingface_hub's ``DatasetCardData``)."""

    license: str
    license_name: str | None
    license_link: str | None


@dataclass(frozen=True)
class HubLicense:
    """The card's licence: a hub licence id (``cc-by-4.0``, ``mit``, ...) or ``other`` with the
    licence's name and a link to its text (the hub shows both)."""

    id: str
    name: str | None = None
    link: str | None = None

    def __post_init__(self) -> None:
        if not self.id or not self.id.replace("-", "").replace(".", "").isalnum():
            raise ReleaseError(f"--license {self.id!r}: give a hub licence id such as cc-by-4.0, or other.")
        if self.id == "other" and not (self.name and self.link):
            raise ReleaseError(
                "--license other needs --license-name and --license-link (the hub shows them beside the data); "
                "or give a hub licence id such as cc-by-4.0."
            )
        if self.link is not None and not self.link.startswith(("https://", "http://")):
            raise ReleaseError(f"--license-link {self.link!r}: an http(s) address of the licence's text.")

    def card_fields(self) -> CardLicence:
        """The dataset card's licence fields (``license_name`` and ``license_link`` for ``other`` only)."""
        if self.id == "other":
            return {"license": self.id, "license_name": self.name, "license_link": self.link}
        return {"license": self.id}

    def text(self) -> str:
        if self.id == "other":
            return f"{self.name} ({self.link})"
        return f"`{self.id}` (https://huggingface.co/docs/hub/repositories-licenses)"


def provenance(doc: Manifest) -> tuple[str, str]:
    """(``synthetic``, ``surveyed`` or ``unrecorded``; a sentence saying so) from what wrote the scenes'
    LAS files (the lineage's ``las_software``)."""
    made = [sc.get("las_software") for sc in doc.lineage["scenes"]]
    if made and all(m and m.startswith(SYNTHETIC_SOFTWARE) for m in made):
        return "synthetic", (
            "**Synthetic.** Every scene is a generated site (siteline's synthetic survey: analytic ground, "
            "buildings, a crane, vehicles and workers scanned by a simulated Zenmuse LiDAR), not a survey: "
            "use it to test a pipeline or to pre-train, and measure on surveyed data."
        )
    if made and all(made) and not any(m.startswith(SYNTHETIC_SOFTWARE) for m in made if m):
        programs = ", ".join(sorted(set(str(m) for m in made)))
        return (
            "surveyed",
            f"**Surveyed.** The scenes are drone LiDAR surveys (their LAS files written by {programs}).",
        )
    return "unrecorded", (
        "**Source not recorded.** Some scenes were ingested before siteline recorded what wrote their LAS "
        "files: whether they are surveyed or synthetic is not stated here."
    )


def _split_rows(doc: Manifest) -> list[str]:
    rows = []
    for split, hub in HUB_SPLITS.items():
        items = [it for it in doc.items if it.split == split]
        if not items:
            continue
        px = [it.size_px[0] * it.size_px[1] for it in items]
        valid = sum(it.valid * n for it, n in zip(items, px, strict=True)) / sum(px)
        changed = sum(it.change_ratio * it.valid * n for it, n in zip(items, px, strict=True)) / sum(px)
        pairs = sorted({it.pair for it in items})
        rows.append(
            f"| {hub} | {len(items)} | {', '.join(map(str, pairs))} | {changed:.1%} | {1 - valid:.1%} |"
        )
    return rows


def _split_rule(doc: Manifest) -> str:
    rule = doc.split_rule
    text = rule.get("rule") if isinstance(rule, dict) else rule
    return str(text) if text else "the release's rule (not recorded in this manifest)"


def _made_lines(doc: Manifest) -> list[str]:
    lin = doc.lineage
    p = PairParams.from_record(lin["parameters"])
    pairs = lin["pairs"]
    radii = [q["radius_m"] for q in pairs]
    lines = [
        f"- {len(lin['scenes'])} scenes (epochs) of one site, {len(pairs)} pairs of consecutive scenes, "
        f"{p.views} synthetic views asked per pair (seed {p.seed}); each view rendered from both scenes' "
        "point clouds with the same camera, so A and B are pixel-aligned.",
        f"- render scale {p.scale}, points drawn as {p.splat} splats"
        + (", edges trimmed" if p.trim_edges else "")
        + f", gaps up to {p.fill_px} px filled; level-of-detail factor {p.lod_factor}.",
        f"- change labels: the {p.label_rule} rule on the 3D points at a radius of "
        f"{min(radii):.3f}-{max(radii):.3f} m (a change smaller than the radius is not labelled), then projected "
        "into both views and OR-ed (symmetric masks).",
    ]
    said: dict[str, list[str]] = {}  # one sentence for the pairs it holds for
    for q in pairs:
        radius = ChangeLabels.from_dict(q["labels"]).radius
        spacing = max(radius.median_spacing_m.values(), default=float("nan")) if radius else float("nan")
        measured = accuracy_text(
            p.label_rule, p.min_region_points, p.trim_edges, spacing, p.surface_probe, p.unsure_edges,
            p.sparse_surfaces,
        )  # fmt: skip
        if measured:
            said.setdefault(measured, []).append(str(q["id"]))
    lines += [f"- pair{'s' if len(ids) > 1 else ''} {', '.join(ids)}: {text}." for text, ids in said.items()]
    return lines


def _use_lines(first: str) -> list[str]:
    """The card's Use section: a snippet that runs on the export as written (the folder put in)."""
    return [
        "## Use",
        "",
        "```python",
        "import numpy as np",
        "import torch",
        "from datasets import load_dataset",
        "",
        'ds = load_dataset("path/to/this/folder")  # or the hub id once pushed',
        f'row = ds["{first}"][0]',
        'a = torch.from_numpy(np.asarray(row["image_a"])).permute(2, 0, 1).float() / 255  # (3, H, W)',
        'b = torch.from_numpy(np.asarray(row["image_b"])).permute(2, 0, 1).float() / 255',
        'label = torch.from_numpy(np.asarray(row["label"])).long()  # (H, W): 0 unchanged, 1 changed, 255 ignore',
        "loss = torch.nn.CrossEntropyLoss(ignore_index=255)  # ignore pixels are not scored",
        'print(row["id"], tuple(a.shape), float((label == 1).float().mean()))',
        "```",
        "",
    ]  # fmt: skip


FIELD_LINES = [
    "## Fields",
    "",
    "| field | holds |",
    "|---|---|",
    "| `id` | the item's id in the release (`<site>_p<pair>_v<view>`) |",
    "| `image_a`, `image_b` | t1 and t2 renders (RGB, 8-bit PNG), pixel-aligned; padded right and bottom to a multiple of 32 px |",
    "| `label` | the change mask, one byte a pixel: **0 unchanged, 1 changed, 255 ignore** (train with `ignore_index=255`); "
    "as an image it looks black: see `label_preview` |",
    "| `label_preview` | the same mask in colour for the hub's viewer: green unchanged, red changed, white ignore |",
    "| `ignore` | 255 where the pixel is ignored, else 0 |",
    "| `split` | the release's split (`val` is the hub's `validation`) |",
    "| `pair`, `view` | the pair of consecutive scenes and the synthetic view's index in it |",
    "| `strategy` | how the view was derived from a real camera (tilt, mirror, forward shift) |",
    "| `coverage`, `valid`, `change_ratio`, `filled` | shares of the rendered image: covered in both epochs, "
    "labelled (not ignore), changed (of the labelled), and filled across gaps between points |",
    "| `width`, `height` | the rendered size inside the padded image, pixels |",
    "| `ignore_causes` | share of the rendered image ignored for each cause: " + ", ".join(f"`{c}`" for c in IGNORE_CAUSES) + " |",
    "| `camera` | the synthetic camera: fx, fy, cx, cy (pixels), `x_cam = rotation x_site + translation` (site-local metres) |",
    "",
]  # fmt: skip


def _limitation_lines(kind: str, ignore_text: str) -> list[str]:
    return [
        "## Limitations",
        "",
        "- The images are renders of point clouds, not photographs: surfaces are as fine as the points (no texture "
        "finer than the point spacing), the sky and unscanned space are empty (ignore), and where a scene has no "
        "colour the images show the height above the ground on a colour ramp (0-25 m).",
        f"- Ignore covers {ignore_text} (no surface, gaps between points, a surface seen in one epoch only, outside "
        "the site fence, ignored classes, padding). Scores that count ignore as unchanged inflate accuracy and mIoU: "
        "exclude it (`ignore_index=255`).",
        "- Labels come from comparing the two point clouds, not from people: a change smaller than the radius, or "
        "hidden in one scene, is not labelled, and the measured precision and recall above bound how far the masks "
        "can be trusted.",
        "- One site and its epochs: views are many but places are few; do not expect a model trained here alone to "
        "carry to other sites, sensors or seasons.",
        *(["- Synthetic: shapes, materials and scanner noise are simulated."] if kind == "synthetic" else []),
        "",
    ]  # fmt: skip


def _card_data(doc: Manifest, shards: Shards, license: HubLicense, kind: str) -> Any:
    """The card's YAML header: licence, task, sizes, splits and their shard files, features."""
    from huggingface_hub import DatasetCardData

    counts = shards.rows
    return DatasetCardData(
        pretty_name=f"{doc.title} (siteline change detection)",
        task_categories=["image-segmentation"],
        task_ids=["semantic-segmentation"],
        size_categories=[size_category(len(doc.items))],
        tags=["change-detection", "construction", "drone", "lidar", "siteline"]
        + (["synthetic"] if kind == "synthetic" else []),
        configs=[
            {
                "config_name": "default",
                "data_files": [{"split": s, "path": f"data/{s}-*.parquet"} for s in counts],
            }
        ],
        dataset_info={
            "features": features()._to_yaml_list(),
            "splits": [
                {"name": s, "num_bytes": shards.num_bytes[s], "num_examples": n} for s, n in counts.items()
            ],
            "download_size": shards.file_bytes,
            "dataset_size": sum(shards.num_bytes.values()),
        },
        **license.card_fields(),
    )


def card(doc: Manifest, shards: Shards, license: HubLicense, stats: ReleaseStats | None = None) -> str:
    """README.md of the export, written for the parquet layout: the hub's YAML header (licence, task,
    sizes, splits and their files, features), what the data is and where it comes from, how to load
    it (a snippet that runs on this folder as written), splits, fields and label meanings, how it was
    made, its limitations, licence and citation."""
    kind, source = provenance(doc)
    counts = shards.rows
    data = _card_data(doc, shards, license, kind)
    ignore = stats["ignore"]["share"] if stats and "ignore" in stats else None
    ignore_text = f"{ignore:.1%} of all pixels" if ignore is not None else "a share of the pixels"
    first = next(iter(counts), "train")
    body = [
        f"# {doc.title}",
        "",
        f"Bi-temporal change detection for construction monitoring: {len(doc.items)} pixel-aligned image pairs "
        "(A: the earlier scene, B: the later one) rendered from drone LiDAR point clouds of a construction site, "
        "each with a symmetric change mask, made by siteline with the iVISION-2DCD method (ICRA 2026). "
        f"Built by siteline {doc.code_version} on {doc.created[:10]}.",
        "",
        source,
        "",
        "![samples: A, B, mask (green unchanged, red changed, white ignore)](montage.png)",
        "",
        *_use_lines(first),
        "## Splits",
        "",
        f"Items are split by {_split_rule(doc)} (views of one pair are correlated: they see the same scenes).",
        "",
        "| split | rows | pairs | changed (of all pixels) | ignore |",
        "|---|---|---|---|---|",
        *_split_rows(doc),
        "",
        *FIELD_LINES,
        "## How it was made",
        "",
        *_made_lines(doc),
        "",
        *_limitation_lines(kind, ignore_text),
        "## Licence",
        "",
        f"{license.text()}.",
        "",
        "## Citation",
        "",
        "```bibtex",
        CITATION,
        "```",
    ]  # fmt: skip
    return f"---\n{data.to_yaml()}\n---\n\n" + "\n".join(body) + "\n"


def export_hf(root: Path, doc: Manifest, work: Path, license: HubLicense) -> Shards:
    """Write the hub export of the release at ``root`` (manifest ``doc``) into the new folder ``work``:
    parquet shards and README.md (the release's montage copied beside it)."""
    shards = write_shards(root, doc, work)
    stats: ReleaseStats | None = (
        json.loads((root / "stats.json").read_text()) if (root / "stats.json").is_file() else None
    )
    if (root / "montage.png").is_file():
        (work / "montage.png").write_bytes((root / "montage.png").read_bytes())
    (work / "README.md").write_text(card(doc, shards, license, stats))
    return shards
