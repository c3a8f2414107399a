"""The enum-like strings siteline persists or accepts, as ``Literal`` types with their values.

Each ``*_VALUES`` tuple is the one list a check constraint, a CLI choice or a validator uses.
"""

from __future__ import annotations

from typing import Literal, get_args

MissionStatus = Literal["received", "ingested", "failed"]
FileKind = Literal["las", "photo", "colmap", "trajectory", "raw", "other"]
Storage = Literal["copy", "reference"]
SceneStatus = Literal["registered", "tiled", "failed"]
CameraSource = Literal["colmap", "xmp", "synthetic", "planned"]
PairStatus = Literal["new", "processed", "superseded"]
ReleaseStatus = Literal["draft", "published"]
StageStatus = Literal["running", "completed", "failed"]
Split = Literal["train", "val", "test"]
NodeOrder = Literal["reversed-morton", "random", "input"]
HoleRule = Literal["ignore", "changed"]
MirrorRule = Literal["aim-site", "reflect"]
Precision = Literal["float32", "float64"]
TaskRunnerKind = Literal["threads", "processes", "dask"]
ReleasePolicy = Literal["every-pair", "on-demand"]
# what A/B show (siteline.render.colour); auto: RGB when both scenes carry it, else intensity, else elevation
ColourChoice = Literal["auto", "rgb", "height", "intensity", "elevation"]
# how A/B are shaded: eye-dome lighting (siteline.render.shading) or not; auto: not (measured on a
# LiDAR-only forest, bench/legible.py: it darkens every splat's rim and brings trees and ground closer)
ShadingChoice = Literal["auto", "edl", "none"]
# whether classes take part in change (siteline.labels.rule); auto: geometry where the scenes classify differently
ChangeRule = Literal["auto", "semantic", "geometry"]

MISSION_STATUSES: tuple[str, ...] = get_args(MissionStatus)
FILE_KINDS: tuple[str, ...] = get_args(FileKind)
STORAGES: tuple[str, ...] = get_args(Storage)
SCENE_STATUSES: tuple[str, ...] = get_args(SceneStatus)
CAMERA_SOURCES: tuple[str, ...] = get_args(CameraSource)
PAIR_STATUSES: tuple[str, ...] = get_args(PairStatus)
RELEASE_STATUSES: tuple[str, ...] = get_args(ReleaseStatus)
STAGE_STATUSES: tuple[str, ...] = get_args(StageStatus)
SPLITS: tuple[str, ...] = get_args(Split)
NODE_ORDERS: tuple[str, ...] = get_args(NodeOrder)
HOLE_RULES: tuple[str, ...] = get_args(HoleRule)
MIRROR_RULES: tuple[str, ...] = get_args(MirrorRule)
PRECISIONS: tuple[str, ...] = get_args(Precision)
TASK_RUNNERS: tuple[str, ...] = get_args(TaskRunnerKind)
RELEASE_POLICIES: tuple[str, ...] = get_args(ReleasePolicy)
COLOUR_CHOICES: tuple[str, ...] = get_args(ColourChoice)
SHADING_CHOICES: tuple[str, ...] = get_args(ShadingChoice)
CHANGE_RULES: tuple[str, ...] = get_args(ChangeRule)
