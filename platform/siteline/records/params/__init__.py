"""What a user sets: the parameter records of the stages (labels, views, renders, pairs, releases),
persisted with their outputs and a release's lineage. Shared primitives like the rest of ``records``,
so a record that carries parameters (a pair's outputs, a site's release settings) holds them typed."""

from siteline.records.params.labels import LabelParams, SurfaceTest
from siteline.records.params.pairs import PairParams
from siteline.records.params.release import ReleaseKnobs, ReleaseParams
from siteline.records.params.render import RenderParams
from siteline.records.params.views import ViewParams

__all__ = [
    "LabelParams",
    "PairParams",
    "ReleaseKnobs",
    "ReleaseParams",
    "RenderParams",
    "SurfaceTest",
    "ViewParams",
]
