"""What the flows show in the Prefect UI: run names and tags, progress artifacts that say what is being
done, and the pair and release artifacts with their images (library markdown, served by `siteline
previews serve`). Orchestration glue only: the figures come from siteline."""

from __future__ import annotations

import re
import time
from pathlib import Path
from typing import Any

from prefect import get_run_logger
from prefect.artifacts import (
    create_image_artifact,
    create_markdown_artifact,
    create_progress_artifact,
    create_table_artifact,
    update_progress_artifact,
)
from prefect.runtime import flow_run

from siteline.config import Settings
from siteline.pipeline import Ingested
from siteline.previews.images import pair_samples, url_of
from siteline.previews.markdown import pair_markdown, release_markdown
from siteline.records.pairs import PairOutput
from siteline.records.release import ReleaseInfo
from siteline.release.manifest import read_manifest


def slug(*parts: Any) -> str:
    """Artifact keys and run-name pieces: lowercase letters, digits and dashes."""
    return re.sub(r"[^a-z0-9-]+", "-", "-".join(str(p) for p in parts).lower()).strip("-")[:100]


def run_tag() -> str:
    """The first 8 characters of this flow run's id: progress artifacts are keyed per run."""
    return str(flow_run.id or "local")[:8]


def tag_run(*extra: str) -> None:
    """Tag the running flow run with ``siteline`` (sub-flows too: the crash automations match it) and
    ``extra`` (site, scene, pair, release: from its parameters, so not known at creation)."""
    from prefect.client.orchestration import get_client

    rid = flow_run.id
    if not rid:
        return
    with get_client(sync_client=True) as client:
        run = client.read_flow_run(rid)
        client.update_flow_run(rid, tags=sorted(set(run.tags) | {"siteline", *extra}))


class RunProgress:
    """A siteline progress callback drawn as one progress artifact of this run (key
    ``progress-<what>-<run>``): ``weights`` say how much of the whole each step is; the description
    names the step and its count; the run log gets a line at every tenth of a step."""

    def __init__(self, what: str, title: str, weights: dict[str, float]) -> None:
        self.title, self.weights = title, weights
        self.done: dict[str, float] = {}
        self.totals: dict[str, int | None] = {}
        self.logged: dict[str, int] = {}
        self.last = 0.0
        self.id = create_progress_artifact(
            0.0, key=slug("progress", what, run_tag()), description=f"{title}: starting"
        )

    def __call__(self, task: str, amount: int, total: int | None) -> None:
        self.done[task] = self.done.get(task, 0) + amount
        if total is not None:
            self.totals[task] = total
        known = self.totals.get(task)
        tenth = int(10 * self.done[task] / known) if known else 0
        if known and tenth > self.logged.get(task, -1):
            self.logged[task] = tenth
            get_run_logger().info("%s: %s %s", self.title, task, counted(task, self.done[task], known))
        now = time.monotonic()
        if now - self.last >= 1.0 or (known and self.done[task] >= known):
            self.last = now
            update_progress_artifact(self.id, self.percent(), description=self._describe(task))

    def percent(self) -> float:
        total_weight = sum(self.weights.values()) or 1.0
        got = sum(
            w * min(1.0, self.done.get(t, 0) / self.totals[t])
            for t, w in self.weights.items()
            if self.totals.get(t)
        )
        return round(100.0 * got / total_weight, 1)

    def _describe(self, task: str) -> str:
        return f"{self.title}: {task} {counted(task, self.done[task], self.totals.get(task))}"

    def finish(self, note: str) -> None:
        update_progress_artifact(self.id, 100.0, description=f"{self.title}: {note}")


# what each library progress task counts (siteline.progress callers), for the UI's words
TASK_UNITS = {
    "hashing": "bytes", "storing": "bytes", "reading points": "points", "reading labels": "points",
    "views": "cameras", "renders": "views", "writing tiles": "tiles", "matching tiles": "tiles",
    "release images": "images", "labels": "",
}  # fmt: skip


def counted(task: str, done: float, total: int | None) -> str:
    """``done`` (of ``total``) in ``task``'s unit: bytes as MB, the rest as counts with their noun."""
    unit = TASK_UNITS.get(task, "")
    if unit == "bytes":
        mb = f"{done / 1e6:,.1f} MB" + (f" of {total / 1e6:,.1f} MB" if total else "")
        return mb
    count = f"{done:,.0f} of {total:,}" if total else f"{done:,.0f}"
    return f"{count} {unit}".rstrip()


def ingest_dashboards(site: str, mission: str, done: Ingested) -> None:
    """The mission's inventory as a table and, when it made a scene, the scene's statistics."""
    res = done.ingest
    rows = {
        "mission": mission, "manifest_sha256": res.manifest_sha256, "files": res.files,
        "created": res.created, "message": res.message,
    }  # fmt: skip
    create_table_artifact(
        [{"item": k, "value": str(v)} for k, v in rows.items()],
        key=slug("mission", site, mission),
        description=f"mission inventory of {mission}",
    )
    scan, tiling = res.scan, done.tiles.tiling if done.tiles is not None else None
    if scan is None:
        return
    reg = res.registration
    stats = {
        "points": scan.point_count, "density_pts_m2": round(scan.density_pts_m2, 2),
        "classes": scan.class_histogram, "unknown_codes": scan.unknown_codes,
        "registration": reg.source, "rms_m": reg.rms_m,
        "alignment_m": reg.alignment.translation_m if reg.alignment else None,
        "tiles": tiling.tiles if tiling else None, "bytes_per_point": tiling.bytes_per_point if tiling else None,
    }  # fmt: skip
    create_table_artifact(
        [{"statistic": k, "value": str(v)} for k, v in stats.items()],
        key=slug("scene", site, res.scene_id),
        description=f"scene {res.scene_id} statistics",
    )


def note(site: str, subject: str, text: str) -> None:
    """A one-paragraph markdown artifact (and a log line): what a run decided not to do, and why."""
    get_run_logger().info("%s", text)
    create_markdown_artifact(
        f"# {subject}\n\n{text}\n", key=slug("note", site, subject), description=text[:200]
    )


def pair_dashboards(settings: Settings, site: str, out: PairOutput, shown: int = 4) -> None:
    """The pair's samples (t1 | t2 | mask) as an image artifact and in its markdown artifact."""
    url = url_of(settings, pair_samples(settings.home, out, shown))
    create_image_artifact(url, key=slug("samples", site, "pair", out.pair_id),
                          description=f"pair {out.pair_id}: t1 | t2 | mask of its first views")  # fmt: skip
    create_markdown_artifact(
        pair_markdown(out, url, min(shown, len(out.views))),
        key=slug("pair", site, out.pair_id),
        description=f"pair {out.pair_id} (scenes {out.t1} -> {out.t2}): {len(out.views)} views",
    )


def release_dashboards(settings: Settings, site: str, info: ReleaseInfo) -> None:
    """The release's montage as an image artifact, its markdown (why, where, sizes, figures) and its
    class balance as a table."""
    root = Path(info.root)
    doc = read_manifest(root)
    url = url_of(settings, root / "montage.png") if info.status == "published" else str(root / "montage.png")
    create_image_artifact(url, key=slug("montage", site, info.name),
                          description=f"{info.name} {info.version}: t1 | t2 | mask samples")  # fmt: skip
    create_markdown_artifact(
        release_markdown(info, doc, url, settings.preview_url),
        key=slug("release", site, info.name),
        description=f"release {info.name} {info.version} ({info.status}): {info.reason}",
    )
    create_table_artifact(
        [{"split": k, **v} for k, v in (doc.stats.get("class_balance") or {}).items()],
        key=slug("balance", site, info.name),
        description=f"class balance of {info.name} {info.version}",
    )
