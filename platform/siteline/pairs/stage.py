"""The pair stage: plan (catalog) -> execute (labels, views, renders; or the outputs already made) ->
record (catalog)."""

from __future__ import annotations

import logging
from collections.abc import Mapping

from siteline.catalog import Catalog
from siteline.catalog.context import StageContext
from siteline.catalog.pairs import record_pair_outputs
from siteline.config import Settings
from siteline.pairs.execute import execute_pair
from siteline.pairs.outputs import find_outputs
from siteline.pairs.plan import plan_pair
from siteline.records.pairs import PairOutput
from siteline.records.params.pairs import PairParams
from siteline.records.runs import StageRun

log = logging.getLogger(__name__)


def process_pair(
    ctx: StageContext,
    pair_id: int,
    params: PairParams | None = None,
    device: str = "cpu",
    label_sets: Mapping[int, int] | None = None,
) -> PairOutput:
    """Labels, views and renders of ``pair_id`` with ``params`` and the classes of ``label_sets``
    (scene id -> label-set version; each scene's newest by default), reused when already made. Their
    catalog rows are written once the outputs are published (also for outputs published by a run that
    died before its commit). One process writes a pair's outputs at a time; another waits, then
    finds them made.

    Both scenes must be tiled (:class:`PairError` names the command otherwise); tiling them is the
    pipeline's job (``siteline.pipeline.process_pairs``), not this stage's."""
    params = params or PairParams()
    started = StageRun("process_pair", f"pair:{pair_id}", run_id=ctx.run_id).started
    with ctx.catalog.lock(f"pair:{pair_id}:outputs"):  # one writer of a pair's outputs at a time
        with ctx.catalog.transaction() as s:
            plan = plan_pair(s, ctx.settings.store, pair_id, params, label_sets)
        found = find_outputs(plan, ctx.settings.store)
        if found is not None:
            log.info(
                "pair %d: outputs %s are already made (%d views)", pair_id, plan.digest, found.view_count
            )
        output = found or execute_pair(plan, ctx.settings.store, device, ctx.progress)
        if found is None or not plan.recorded:
            parameters = params.to_dict() | {"radius_m": output.radius_m}
            with ctx.catalog.transaction() as s:
                record_pair_outputs(
                    s, output, StageRun("process_pair", f"pair:{pair_id}", parameters, started, ctx.run_id)
                )
    return output


def find_pair_output(
    catalog: Catalog,
    settings: Settings,
    pair_id: int,
    params: PairParams,
    label_sets: Mapping[int, int] | None = None,
) -> PairOutput | None:
    """The published outputs of ``pair_id`` with ``params`` and ``label_sets`` (each scene's newest by
    default), None when they were not made (a read: nothing is written)."""
    with catalog.transaction() as s:
        plan = plan_pair(s, settings.store, pair_id, params, label_sets)
    return find_outputs(plan, settings.store)
