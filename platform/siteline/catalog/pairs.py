"""Catalog reads and writes of pair outputs: views and renders keyed by the parameters' digest.
Functions take a session and never commit: the caller owns the transaction."""

from __future__ import annotations

import sqlalchemy as sa
from sqlalchemy.orm import Session

from siteline.catalog.addresses import to_record
from siteline.catalog.models import Camera as CameraRow
from siteline.catalog.models import Pair, Render, Scene, Site, View
from siteline.catalog.sites import site_name
from siteline.catalog.stages import add_completed
from siteline.errors import NotFoundError
from siteline.records.pairs import PairOutput
from siteline.records.runs import StageRun
from siteline.records.site import SiteKey
from siteline.stores import join


def get_pair(session: Session, pair_id: int) -> Pair:
    """The pair row ``pair_id``; :class:`NotFoundError` when there is none."""
    pair = session.get(Pair, pair_id)
    if pair is None:
        raise NotFoundError(f"no pair with id {pair_id}.")
    return pair


def pair_view_ids(session: Session, pair_id: int, digest: str) -> dict[int, int]:
    """View index -> view row id of ``pair_id`` processed with the parameters of ``digest``."""
    rows = session.execute(
        sa.select(View.index, View.id).where(View.pair_id == pair_id, View.param_digest == digest)
    ).all()
    return dict(rows)


def unprocessed_pairs(session: Session, pair_ids: list[int]) -> list[int]:
    """Those of ``pair_ids`` with no recorded outputs under any parameters: work nobody did yet."""
    done = set(
        session.execute(sa.select(View.pair_id).where(View.pair_id.in_(pair_ids)).distinct()).scalars()
    )
    return [pid for pid in pair_ids if pid not in done]


def record_pair_outputs(session: Session, output: PairOutput, run: StageRun) -> None:
    """The rows of one pair's outputs, published in the store at ``output.root``: the pair's radius,
    status and parameters, a view per rendered view (replacing earlier rows of the same digest), a
    render per view and side, and the stage run."""
    pair = get_pair(session, output.pair_id)
    params, digest = output.params.to_dict(), output.digest
    pair.radius_m = output.radius_m
    if pair.status != "superseded":  # a superseded pair stays out of new releases
        pair.status = "processed"
    labels = output.labels.to_dict() | {"uri": to_record(output.labels.uri)}
    pair.parameters = {**(pair.parameters or {}), digest: {"params": params, "labels": labels}}
    session.execute(sa.delete(View).where(View.pair_id == pair.id, View.param_digest == digest))
    cams = dict(
        session.execute(
            sa.select(CameraRow.image_name, CameraRow.id).where(CameraRow.scene_id == pair.t2_scene_id)
        ).all()
    )
    for rec in output.views:
        view = View(
            pair_id=pair.id, param_digest=digest, index=rec.index, strategy=rec.strategy,
            parent_camera_id=cams.get(rec.parent), parameters=rec.params.to_dict(), camera=rec.camera.to_dict(),
        )  # fmt: skip
        session.add(view)
        session.flush()
        for side, sid, coverage in (
            ("A", pair.t1_scene_id, rec.coverage_a),
            ("B", pair.t2_scene_id, rec.coverage_b),
        ):
            session.add(
                Render(
                    view_id=view.id, scene_id=sid, scale=params["scale"], point_size_px=params["point_size_px"],
                    coverage=coverage, change_ratio=rec.change_ratio,
                    paths={"image": join(output.root, side, rec.file), "label": join(output.root, "label", rec.file)},
                )
            )  # fmt: skip
    add_completed(session, run)


def ensure_pair(session: Session, site: Site, t1: Scene, t2: Scene) -> Pair:
    pair = session.execute(
        sa.select(Pair).where(Pair.t1_scene_id == t1.id, Pair.t2_scene_id == t2.id)
    ).scalar_one_or_none()
    if pair is None:
        pair = Pair(site_id=site.id, t1_scene_id=t1.id, t2_scene_id=t2.id)
        session.add(pair)
        session.flush()
    return pair


def list_pairs(session: Session, site: SiteKey) -> list[Pair]:
    """The site's pairs of consecutive scenes, in capture order (superseded pairs left out)."""
    t1 = sa.orm.aliased(Scene)
    return list(
        session.execute(
            sa.select(Pair)
            .join(t1, Pair.t1_scene_id == t1.id)
            .where(Pair.site_id == site.id, Pair.status != "superseded")
            .order_by(t1.capture_time)
        ).scalars()
    )


def supersede_pair(session: Session, t1_id: int, t2_id: int) -> None:
    """Mark the pair (t1, t2) superseded: a scene captured between them arrived later. Its outputs and
    the releases that used it stay; new releases draw on the consecutive pairs."""
    session.execute(
        sa.update(Pair)
        .where(Pair.t1_scene_id == t1_id, Pair.t2_scene_id == t2_id)
        .values(status="superseded")
    )


def pair_ids_of_scene(session: Session, scene_id: int) -> list[int]:
    """Ids of the pairs ``scene_id`` belongs to (as t1 or t2), ascending."""
    return list(
        session.execute(
            sa.select(Pair.id)
            .where(
                (Pair.t1_scene_id == scene_id) | (Pair.t2_scene_id == scene_id), Pair.status != "superseded"
            )
            .order_by(Pair.id)
        ).scalars()
    )


def site_name_of_pair(session: Session, pair_id: int) -> str:
    """The name of the site of pair ``pair_id``; :class:`NotFoundError` when there is none."""
    pair = session.get(Pair, pair_id)
    if pair is None:
        raise NotFoundError(f"no pair with id {pair_id}.")
    return site_name(session, pair.site_id)


def scene_ids_of_pairs(session: Session, pair_ids: list[int]) -> list[int]:
    """The scenes the pairs ``pair_ids`` join, each once, in pair order (unknown pairs are skipped)."""
    out: list[int] = []
    for pid in pair_ids:
        pair = session.get(Pair, pid)
        if pair is not None:
            out += [sid for sid in (pair.t1_scene_id, pair.t2_scene_id) if sid not in out]
    return out
