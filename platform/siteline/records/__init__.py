"""Typed records for everything that crosses a stage or the catalog (shared primitives: stages build
them, ``siteline.catalog`` records and returns them, the CLI and flows report them)."""

from siteline.records.enums import (
    CameraSource,
    FileKind,
    HoleRule,
    MirrorRule,
    NodeOrder,
    ReleasePolicy,
    ReleaseStatus,
    SceneStatus,
    Split,
    Storage,
    TaskRunnerKind,
)
from siteline.records.labelsets import LabelSetImport, LabelSetRef
from siteline.records.mission import CheckedMission, FileEntry, LasLocation, MissionManifest
from siteline.records.pairs import PairOutput, PairVersions, RenderedView
from siteline.records.release import DraftRelease, ReleaseInfo, ReleaseItem
from siteline.records.runs import StageRun
from siteline.records.scan import LasScan
from siteline.records.scene import SceneStatistics, SceneView
from siteline.records.tiling import NodeTable, SceneTiling, TileSource, TileSpec

__all__ = [
    "CameraSource",
    "CheckedMission",
    "DraftRelease",
    "FileEntry",
    "FileKind",
    "HoleRule",
    "LabelSetImport",
    "LabelSetRef",
    "LasLocation",
    "LasScan",
    "MirrorRule",
    "MissionManifest",
    "NodeTable",
    "NodeOrder",
    "PairOutput",
    "PairVersions",
    "ReleaseInfo",
    "ReleaseItem",
    "ReleasePolicy",
    "ReleaseStatus",
    "RenderedView",
    "SceneStatistics",
    "SceneStatus",
    "SceneView",
    "SceneTiling",
    "Split",
    "StageRun",
    "Storage",
    "TaskRunnerKind",
    "TileSource",
    "TileSpec",
]
