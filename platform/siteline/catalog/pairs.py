"""Catalog reads and writes of pair outputs: views and renders keyed by the parameters' digest.
Functions take a session and never commit: the caller owns the transaction."""

from __future__ import annotations

from typing import Any

import sqlalchemy as sa
from sqlalchemy.orm import Session

from siteline.catalog.models import Camera as CameraRow
from siteline.catalog.models import Pair, Render, View
from siteline.errors import NotFoundError
from siteline.stores import join


def pair_view_ids(session: Session, pair_id: int, digest: str) -> dict[int, int]:
    """View index -> view row id of ``pair_id`` processed with the parameters of ``digest``."""
    rows = session.execute(
        sa.select(View.index, View.id).where(View.pair_id == pair_id, View.param_digest == digest)
    ).all()
    return dict(rows)


def record_pair_outputs(
    session: Session,
    pair_id: int,
    digest: str,
    params: dict[str, Any],
    radius_m: float,
    labels: dict[str, Any],
    views: list[dict[str, Any]],
    root: str,
) -> None:
    """The rows of one pair's outputs in the store at ``root``: the pair's radius, status and
    parameters, a view per record of ``views`` (replacing earlier rows of the same digest) and a render
    per view and side. ``params``: the pair parameters (``scale``, ``point_size_px`` read from it)."""
    pair = session.get(Pair, pair_id)
    if pair is None:
        raise NotFoundError(f"no pair with id {pair_id}.")
    pair.radius_m = radius_m
    pair.status = "processed"
    pair.parameters = {**(pair.parameters or {}), digest: {"params": params, "labels": labels}}
    session.execute(sa.delete(View).where(View.pair_id == pair_id, View.param_digest == digest))
    cams = dict(
        session.execute(
            sa.select(CameraRow.image_name, CameraRow.id).where(CameraRow.scene_id == pair.t2_scene_id)
        ).all()
    )
    for rec in views:
        view = View(
            pair_id=pair_id,
            param_digest=digest,
            index=rec["index"],
            strategy=rec["strategy"],
            parent_camera_id=cams.get(rec["parent"]),
            parameters=rec["params"],
            camera=rec["camera"],
        )
        session.add(view)
        session.flush()
        for side, sid in (("A", pair.t1_scene_id), ("B", pair.t2_scene_id)):
            session.add(
                Render(
                    view_id=view.id,
                    scene_id=sid,
                    scale=params["scale"],
                    point_size_px=params["point_size_px"],
                    coverage=rec["coverage_a" if side == "A" else "coverage_b"],
                    change_ratio=rec["change_ratio"],
                    paths={
                        "image": join(root, side, rec["file"]),
                        "label": join(root, "label", rec["file"]),
                    },
                )
            )
