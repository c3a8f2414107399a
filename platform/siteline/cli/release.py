"""``siteline release ...``, ``siteline train`` and ``siteline evaluate``."""

from __future__ import annotations

from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from siteline.catalog.context import StageContext
from siteline.catalog.releases import (
    get_release,
    list_releases,
    query_items,
    release_item_files,
    release_location,
    release_record,
)
from siteline.cli.common import (
    JsonOption,
    catalog,
    console,
    emit,
    print_record,
    print_table,
    progress_bars,
    settings,
)
from siteline.cli.knobs import with_knob_options
from siteline.errors import ReleaseError
from siteline.records.params.release import ReleaseKnobs
from siteline.records.release import ReleaseInfo, ReleaseOptions
from siteline.release.manifest import verify_files
from siteline.release.query import diff_releases
from siteline.schema import json_int, json_object

if TYPE_CHECKING:
    from siteline.release.score import ScoreRecord

app = typer.Typer(help="Versioned, immutable dataset releases.", no_args_is_help=True)


def _both_metrics(result: ScoreRecord) -> dict[str, float | int | None]:
    """Split-level scores (one confusion matrix) and the paper's per-image mIoU, each named."""
    split = {f"{k} (split)": v for k, v in result["scores"].items()}
    paper = result["scores_per_image"]
    return split | {
        "miou (per image, paper/Pylon)": paper["miou"],
        "iou_changed (per image, paper/Pylon)": paper["iou_changed"],
    }


@app.command("build")
@with_knob_options
def build(
    site: str = typer.Option(..., "--site", help="Site whose pairs the release draws on."),
    name: str = typer.Option(..., "--name", help="Release name."),
    pairs: list[int] | None = typer.Option(
        None, "--pairs", help="Pair ids (repeatable; default: every pair of the site)."
    ),
    version: str | None = typer.Option(
        None, "--version", help="Version (default: next, major bump when labels, pairs or knobs change)."
    ),
    device: str = typer.Option("cpu", "--device", help="torch device for rendering."),
    label_set: list[str] | None = typer.Option(
        None,
        "--label-set",
        help="SCENE=VERSION: use that label-set version of a scene (repeatable; default: each scene's newest).",
    ),
    publish: bool = typer.Option(False, "--publish", help="Publish the draft once built."),
    as_json: bool = JsonOption,
    *,
    knobs: ReleaseKnobs,
) -> None:
    """Build a draft release with the site's release settings (`siteline site show`; the options
    below override them for this build): labels, views and renders of every pair, splits, manifest,
    datasheet. Nothing is built when the latest version already has these inputs."""
    from siteline import pipeline

    with catalog() as cat, progress_bars(as_json) as bars:
        options = ReleaseOptions(pairs or None, version, parse_label_sets(label_set or []), publish, device)
        info = pipeline.release(StageContext(cat, settings(), progress=bars), site, name, knobs, options)
    emit(as_json, info.to_dict(), lambda: console.print(build_message(info)))


def build_message(info: ReleaseInfo) -> str:
    """What `release build` says about the release it built, or found up to date."""
    if info.up_to_date:
        return (
            f"release {info.name} is up to date: {info.version} ({info.status}) has the same pairs, outputs, "
            f"label sets and parameters; nothing was built ({info.root})"
        )
    then = (
        ""
        if info.status == "published"
        else f"; publish with `siteline release publish {info.name} {info.version}`"
    )
    return (
        f"{info.status} {info.name} {info.version} ({info.reason}): {info.items} items at {info.root}{then}"
    )


def parse_label_sets(values: list[str]) -> dict[int, int] | None:
    """``SCENE=VERSION`` strings -> {scene id: version}; ReleaseError on a malformed one."""
    out: dict[int, int] = {}
    for text in values:
        scene, _, version = text.partition("=")
        try:
            out[int(scene)] = int(version)
        except ValueError as exc:
            raise ReleaseError(f"--label-set {text!r}: write SCENE=VERSION, e.g. --label-set 3=2.") from exc
    return out or None


@app.command("publish")
def publish(
    name: str = typer.Argument(...), version: str = typer.Argument(...), as_json: bool = JsonOption
) -> None:
    """Publish a draft: verify its checksums, move it into place read-only. Never rewrites a version."""
    from siteline.release.stage import publish_release

    with catalog() as cat:
        info = publish_release(StageContext(cat, settings()), name, version)
    emit(as_json, info.to_dict(), lambda: console.print(f"published {name} {version} at {info.root}"))


@app.command("list")
def list_(name: str | None = typer.Option(None, "--name"), as_json: bool = JsonOption) -> None:
    """List releases."""
    with catalog() as cat, cat.transaction() as s:
        records = [release_record(s, r) for r in list_releases(s, name)]
    emit(
        as_json,
        records,
        lambda: print_table(
            "releases",
            ["name", "version", "status", "items", "root"],
            [
                [
                    r["name"],
                    r["version"],
                    r["status"],
                    sum(map(json_int, json_object(r["items"]).values())),
                    r["root"],
                ]
                for r in records
            ],
        ),
    )


@app.command("show")
def show(
    name: str = typer.Argument(...), version: str = typer.Argument(...), as_json: bool = JsonOption
) -> None:
    """Show one release."""
    with catalog() as cat, cat.transaction() as s:
        record = release_record(s, get_release(s, name, version))
    emit(as_json, record, lambda: print_record(f"release {name} {version}", _in_words(record)))


def _in_words(record: dict[str, object]) -> dict[str, object]:
    """``record`` with each pair's changes seen in words (one row a pair), not as a document."""
    from siteline.records.pairs import ChangesSeen

    seen = record.get("changes_seen")
    out = {k: v for k, v in record.items() if k != "changes_seen"}
    if isinstance(seen, dict):
        for pid, doc in seen.items():
            out[f"changes seen, pair {pid}"] = ChangesSeen.from_dict(doc).summary()
    return out


@app.command("diff")
def diff(
    name: str = typer.Argument(...),
    v1: str = typer.Argument(...),
    v2: str = typer.Argument(...),
    as_json: bool = JsonOption,
) -> None:
    """Pairs, parameters, label sets and files that differ between two versions."""
    with catalog() as cat, cat.transaction() as s:
        record = diff_releases(s, name, v1, v2)
    emit(as_json, record, lambda: print_record(f"{name} {v1} -> {v2}", record))


@app.command("verify")
def verify(
    name: str = typer.Argument(...), version: str = typer.Argument(...), as_json: bool = JsonOption
) -> None:
    """Recompute every checksum of a release and check its manifest against the catalog's record;
    name each file that differs and any state a killed build or publish left (exit status 1 if any)."""
    from siteline.release.repair import inspect_release

    with catalog() as cat, cat.transaction() as s:
        root, _ = release_location(s, name, version)
        rel = get_release(s, name, version)
        recorded, files = rel.manifest_sha256, release_item_files(s, rel.id)
        findings = inspect_release(s, settings(), name, version)
    problems = [
        f.message + (f" Mend it with `siteline release repair {name} {version}`." if f.mendable else "")
        for f in findings
    ]
    if root.is_dir() or recorded is not None:
        problems += verify_files(root, recorded, files)
    emit(
        as_json,
        {"name": name, "version": version, "root": str(root), "ok": not problems, "problems": problems},
        lambda: console.print(
            "\n".join([f"{name} {version} (checked {root}):", *problems])
            if problems
            else f"{name} {version}: every checksum matches the catalog's manifest (checked {root})"
        ),
    )
    if problems:
        raise typer.Exit(1)


@app.command("repair")
def repair(
    name: str = typer.Argument(..., help="Release name."),
    version: str | None = typer.Argument(None, help="Version (default: every version of the name)."),
    as_json: bool = JsonOption,
) -> None:
    """Mend what a killed build or publish left: finish a publish that moved the folder but was not
    recorded, make a published version read-only, remove a draft the catalog does not record."""
    from siteline.release.repair import repair_release

    with catalog() as cat:
        done = repair_release(StageContext(cat, settings()), name, version)
    emit(
        as_json,
        {"name": name, "version": version, "repaired": done},
        lambda: console.print("\n".join(done) if done else f"release {name}: nothing to repair"),
    )


@app.command("browse")
def browse(
    name: str = typer.Argument(...),
    version: str = typer.Argument(...),
    out: Path | None = typer.Option(
        None,
        "--out",
        help="HTML file (or folder) to write (default: <version>.html beside the release's folder).",
    ),
    force: bool = typer.Option(
        False,
        "--force",
        help="Replace an existing page at --out (or <name>-<version>.html in the --out folder).",
    ),
    as_json: bool = JsonOption,
) -> None:
    """Write the release browser (draft or published) as one HTML page beside the release: a grid of
    its items with filters, each item's A and B under a swipe with its mask. Open it from the disk;
    `siteline previews serve` serves the same page with the 3D viewer at /browse/NAME/VERSION/."""
    from siteline.previews.browser import write_browser

    with catalog() as cat, cat.transaction() as s:
        root, status = release_location(s, name, version)
    page = write_browser(root, out, status, replace=force or out is None)
    emit(
        as_json,
        {"name": name, "version": version, "status": status, "page": str(page)},
        lambda: console.print(f"release browser of {name} {version} ({status}): {page.as_uri()}"),
    )


@app.command("export")
def export(
    name: str = typer.Argument(...),
    version: str = typer.Argument(...),
    profile: str = typer.Option(
        ...,
        "--profile",
        help="opencd, torchgeo-levircd, torchgeo-levircdplus, changemamba, changeformer, torchange, or hf "
        "(Hugging Face datasets: parquet shards and a dataset card).",
    ),
    out: Path = typer.Option(..., "--out", help="New folder for the export (outside the release)."),
    copy: bool = typer.Option(False, "--copy", help="Copy files instead of relative symlinks."),
    license_id: str | None = typer.Option(
        None,
        "--license",
        help="hf (required): the card's licence, a hub licence id (cc-by-4.0, mit, ...) or other.",
    ),
    license_name: str | None = typer.Option(
        None, "--license-name", help="hf, with --license other: the licence's name."
    ),
    license_link: str | None = typer.Option(
        None, "--license-link", help="hf, with --license other: an http(s) address of the licence's text."
    ),
    as_json: bool = JsonOption,
) -> None:
    """Lay a release out as one toolbox's stock loader expects (or as a Hugging Face dataset); print the
    setting that honours ignore."""
    from siteline.release.export import export_release
    from siteline.release.hub import HubLicense

    hub_license = HubLicense(license_id, license_name, license_link) if license_id is not None else None

    with catalog() as cat, cat.transaction() as s:
        root, _ = release_location(s, name, version)
        rel = get_release(s, name, version)
        recorded, files = rel.manifest_sha256, release_item_files(s, rel.id)
    from siteline.stores import layout

    # an export trusts nothing on disk it has not checked: the same checks as `release verify`
    problems = verify_files(root, recorded, files) if root.is_dir() or recorded is not None else []
    if problems:
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        raise ReleaseError(
            f"release {name} {version} differs from what was published: {problems[0]}{more}; nothing exported. "
            f"`siteline release verify {name} {version}` lists every difference."
        )
    result = export_release(
        root, profile, out, copy=copy, protected=layout.releases(settings().home), license=hub_license
    )
    emit(
        as_json,
        result.to_dict(),
        lambda: console.print(
            f"exported {name} {version} for {profile} to {result.out}: {result.files} files, "
            f"images per split {result.splits}"
            + (
                f", splits mapped {result.split_map}"
                if any(k != v for k, v in result.split_map.items())
                else ""
            )
            + (
                f"\n{result.label_rule}."
                if profile == "hf"
                else f"\nlabel/ is LEVIR-CD 0/255; the tool reads it as: {result.label_rule}."
            )
            + f"\n{result.honour_ignore}."
            + (f"\nnote: {result.note}." if result.note else "")
        ),
    )


@app.command("score")
def score(
    name: str = typer.Argument(...),
    version: str = typer.Argument(...),
    split: str = typer.Option("test", "--split"),
    pred: Path = typer.Option(
        ..., "--pred", help="Folder of predictions, 0/255 or 0/1, named <id>.png or as an export named them."
    ),
    pred_size: str | None = typer.Option(
        None,
        "--pred-size",
        help="WxH of the predictions when the tool resized the images (ChangeFormer: 256x256).",
    ),
    out: Path | None = typer.Option(None, "--out", help="Also write the results JSON here."),
    as_json: bool = JsonOption,
) -> None:
    """Score predictions against the ignore-aware truth: one confusion matrix over the split."""
    import json

    from siteline.release.score import score_predictions

    with catalog() as cat, cat.transaction() as s:
        root, _ = release_location(s, name, version)
    from siteline.release.score import parse_size

    result = score_predictions(root, split, pred, parse_size(pred_size) if pred_size else None)
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(result, indent=1) + "\n")
    emit(
        as_json,
        result,
        lambda: print_record(
            f"{name} {version} {split}: {result['images']} predictions",
            _both_metrics(result) | ({"results": str(out)} if out else {}),
        ),
    )


@app.command("query")
def query(
    name: str = typer.Argument(...),
    version: str = typer.Argument(...),
    min_change_ratio: float | None = typer.Option(
        None, "--min-change-ratio", help="Only views whose change ratio is above this."
    ),
    split: str | None = typer.Option(None, "--split"),
    since: datetime | None = typer.Option(
        None, "--since", help="Pairs whose t1 was captured on or after (ISO date)."
    ),
    until: datetime | None = typer.Option(
        None, "--until", help="Pairs whose t2 was captured on or before (ISO date)."
    ),
    min_change_visible: float | None = typer.Option(
        None,
        "--min-change-visible",
        help="Only views whose changed pixels show their change at least this much (the share whose colour "
        "differs between A and B); views with nothing changed are left out.",
    ),
    as_json: bool = JsonOption,
) -> None:
    """Query a release's views from the catalog."""
    from datetime import UTC

    since = since.replace(tzinfo=since.tzinfo or UTC) if since else None
    until = until.replace(tzinfo=until.tzinfo or UTC) if until else None
    with catalog() as cat, cat.transaction() as s:
        rows = query_items(s, name, version, min_change_ratio, split, since, until, min_change_visible)
    emit(
        as_json,
        rows,
        lambda: print_table(
            f"{name} {version}: {len(rows)} views",
            ["id", "split", "pair", "change ratio", "change visible"],
            [
                [
                    r["id"],
                    r["split"],
                    r["pair"],
                    f"{r['change_ratio']:.3f}",
                    "-" if r["change_visible"] is None else f"{r['change_visible']:.2f}",
                ]
                for r in rows
            ],
        ),
    )


def train_cmd(
    name: str = typer.Option(..., "--release", help="Release name."),
    version: str = typer.Option(..., "--version"),
    out: Path = typer.Option(..., "--out", help="Folder for model.pt and train_log.json."),
    epochs: int = typer.Option(1, "--epochs"),
    max_iters: int | None = typer.Option(None, "--max-iters"),
    crop: int = typer.Option(256, "--crop"),
    device: str = typer.Option("cpu", "--device"),
    workers: int = typer.Option(0, "--workers", help="DataLoader worker processes."),
    as_json: bool = JsonOption,
) -> None:
    """Train FC-Siam-diff on a release (SGD 1e-3, momentum 0.9, wd 1e-4, poly 0.9, batch 4)."""
    from siteline.baseline import TrainParams, train

    with catalog() as cat, cat.transaction() as s:
        root, _ = release_location(s, name, version)
    from rich.progress import Progress

    with Progress(console=console, transient=True, disable=as_json) as bar:
        task = bar.add_task("training", total=None)
        config = TrainParams(epochs=epochs, max_iters=max_iters, crop=crop, device=device, workers=workers)
        log = train(
            root,
            out,
            config,
            progress=lambda it, total, loss: bar.update(
                task, completed=it, total=total, description=f"training loss {loss:.3f}"
            ),
        )
    losses = log["losses"]
    summary = {
        "release": log["release"], "iterations": log["iterations"], "seconds": log["seconds"],
        "parameters": log["parameters"], "first_loss": losses[0] if losses else None,
        "last_loss": losses[-1] if losses else None,
    }  # fmt: skip
    emit(as_json, summary, lambda: print_record("training", summary))


def evaluate_cmd(
    name: str = typer.Option(..., "--release"),
    version: str = typer.Option(..., "--version"),
    checkpoint: Path = typer.Option(..., "--checkpoint"),
    split: str = typer.Option("test", "--split"),
    out: Path = typer.Option(..., "--out", help="Results JSON."),
    device: str = typer.Option("cpu", "--device"),
    as_json: bool = JsonOption,
) -> None:
    """Evaluate a checkpoint on a split: one confusion matrix, IoU/mIoU/F1/OA/kappa, results JSON."""
    from siteline.baseline import evaluate

    with catalog() as cat, cat.transaction() as s:
        root, _ = release_location(s, name, version)
    result = evaluate(root, checkpoint, out, split, device)
    emit(
        as_json,
        result,
        lambda: print_record(f"{name} {version} {split}", _both_metrics(result) | {"results": str(out)}),
    )
