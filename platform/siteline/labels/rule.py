"""A pair's change rule: whether classes take part in 3D change (DESIGN.md §4) or only geometry does,
resolved from the two scenes' class histograms.

Two epochs classified by different schemes (one separates vegetation, the other leaves it
unclassified; one has ground, the other none) make the semantic rule flag every such point as
changed. The scheme classes below are the ones a classification scheme either produces or does not,
on any outdoor scene; construction classes (crane, material, vehicle, ...) come and go as real change
and are not judged.
"""

from __future__ import annotations

from collections.abc import Mapping

from siteline.errors import PairError
from siteline.records.enums import CHANGE_RULES
from siteline.records.pairs import ChangeRulePlan
from siteline.site.taxonomy import Taxonomy

SCHEME_CLASSES = ("ground", "vegetation", "unclassified")
# a scheme class is present in a scene above this share of its kept points, absent below the other
PRESENT_SHARE = 0.01
ABSENT_SHARE = 0.0005


def _shares(histogram: Mapping[str, int], taxonomy: Taxonomy) -> dict[str, float]:
    kept = {c.name for c in taxonomy.classes if not c.ignore}
    total = sum(n for name, n in histogram.items() if name in kept)
    return {name: histogram.get(name, 0) / total for name in SCHEME_CLASSES} if total else {}


def scheme_differences(
    first: tuple[int, Mapping[str, int]], second: tuple[int, Mapping[str, int]], taxonomy: Taxonomy
) -> tuple[str, ...]:
    """How two scenes' classifications differ, one sentence per scheme class present in one scene
    (at least 1 % of its kept points) and absent from the other (under 0.05 %). ``first`` and
    ``second``: (scene id, points per class name)."""
    (id1, h1), (id2, h2) = first, second
    s1, s2 = _shares(h1, taxonomy), _shares(h2, taxonomy)
    if not s1 or not s2:
        return ()
    out = []
    for name in SCHEME_CLASSES:
        if name not in {c.name for c in taxonomy.classes}:
            continue
        for (a, sa), (b, sb) in (((id1, s1[name]), (id2, s2[name])), ((id2, s2[name]), (id1, s1[name]))):
            if sa >= PRESENT_SHARE and sb < ABSENT_SHARE:
                out.append(f"{name} is {sa:.1%} of scene {a}'s kept points and {sb:.2%} of scene {b}'s")
    return tuple(out)


def resolve_change_rule(
    choice: str,
    first: tuple[int, Mapping[str, int]],
    second: tuple[int, Mapping[str, int]],
    taxonomy: Taxonomy,
) -> ChangeRulePlan:
    """The rule of a pair whose scenes hold the class histograms of ``first`` and ``second`` ((scene
    id, points per class name), from the label sets the pair uses): ``auto`` takes ``geometry`` when
    their schemes differ (:func:`scheme_differences`), else ``semantic``; an explicit choice is kept
    and the differences are still stated."""
    if choice not in CHANGE_RULES:
        raise PairError(f"change rule {choice!r}: use one of {', '.join(CHANGE_RULES)}.")
    diff = scheme_differences(first, second, taxonomy)
    if choice != "auto":
        return ChangeRulePlan(choice, "asked for", diff)
    if diff:
        return ChangeRulePlan("geometry", "the scenes classify differently (auto)", diff)
    return ChangeRulePlan("semantic", "the scenes classify alike (auto)", diff)
