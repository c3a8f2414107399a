"""A pair's outputs once made: read back from the store (no rendering, no torch)."""

from __future__ import annotations

import json

from siteline.pairs.plan import PairPlan
from siteline.records.pairs import (
    ChangeLabels,
    ChangeRulePlan,
    ColourPlan,
    Drawn,
    GroundUsed,
    PairOutput,
    PairSummary,
    RenderedView,
)
from siteline.stores import Store, join


def output_of(plan: PairPlan, doc: PairSummary) -> PairOutput:
    """The outputs of ``plan`` its summary ``doc`` describes."""
    return PairOutput(
        plan.pair_id, plan.t1.id, plan.t2.id, float(doc["radius_m"]), plan.root,
        tuple(RenderedView.from_dict(v) for v in doc["views"]), ChangeLabels.from_dict(doc["labels"]), plan.versions,
        plan.digest, plan.params, ColourPlan.from_dict(doc.get("colour") or {"source": "rgb"}),
        doc.get("fence", "site fence"), ChangeRulePlan.from_dict(doc.get("change_rule")), Drawn.from_dict(doc),
        GroundUsed.from_dict(doc.get("ground")),
    )  # fmt: skip


def find_outputs(plan: PairPlan, store: Store) -> PairOutput | None:
    """The outputs of ``plan`` when they are published in the store, else None (a read only)."""
    if not store.is_complete(plan.root):
        return None
    return output_of(plan, json.loads(store.read_bytes(join(plan.root, "summary.json"))))
