"""Catalog tables (DESIGN.md §1, §8): sites, missions and their files, scenes, cameras, label sets,
pairs, views, renders, releases and their items, and stage runs.

Store addresses (``*_uri`` columns, a render's paths) are recorded relative to the store root or
the home (siteline.catalog.addresses) and read back as absolute addresses; so are a tiling's ``uri``
(through ``catalog.scenes.scene_statistics``); a pair's labels' ``uri`` in its parameters is recorded
the same way (``addresses.from_record`` reads it).

Coordinates and bounds are float64 in the site-local frame unless a name says otherwise; the site
origin is float64 in the site CRS. Poses are COLMAP ``cam_from_world`` (row-major R, t).
"""

from __future__ import annotations

from datetime import datetime
from typing import TypedDict

import sqlalchemy as sa
from sqlalchemy.orm import Mapped, mapped_column, relationship

from siteline.catalog.addresses import StoreAddress, StoreAddresses
from siteline.catalog.base import Base, Float64, UTCDateTime, utcnow
from siteline.records.enums import (
    CAMERA_SOURCES,
    FILE_KINDS,
    MISSION_STATUSES,
    RELEASE_STATUSES,
    SCENE_STATUSES,
    SPLITS,
    STAGE_STATUSES,
)
from siteline.records.release import ReleaseRecord
from siteline.schema import JSON
from siteline.site.taxonomy import TaxonomyDoc


def _in(column: str, values: tuple[str, ...]) -> str:
    return f"{column} IN ({', '.join(repr(v) for v in values)})"


class SiteVersion(TypedDict):
    """An earlier version of a site's taxonomy and fence (site-local metres), and when it was replaced."""

    version: int
    taxonomy: TaxonomyDoc
    fence: list[list[float]] | None
    replaced_at: str


class Site(Base):
    __tablename__ = "site"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(sa.String(64), unique=True)
    crs: Mapped[str] = mapped_column(sa.Text)
    origin_x: Mapped[float] = mapped_column(Float64)
    origin_y: Mapped[float] = mapped_column(Float64)
    origin_z: Mapped[float] = mapped_column(Float64)
    fence: Mapped[list[list[float]] | None] = mapped_column(sa.JSON, nullable=True)
    taxonomy: Mapped[TaxonomyDoc] = mapped_column(sa.JSON)
    tile_size_m: Mapped[float] = mapped_column(Float64)
    # siteline.release.knobs.ReleaseKnobs.to_dict(): preset and knobs; {} means auto from the cameras
    release_settings: Mapped[dict[str, JSON]] = mapped_column(sa.JSON, default=dict, server_default="{}")
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    # the version of the taxonomy and fence above (1 at creation; `site update --taxonomy/--fence`
    # adds one) and the earlier versions: [{"version", "taxonomy", "fence", "replaced_at"}]
    version: Mapped[int] = mapped_column(sa.Integer, default=1, server_default="1")
    history: Mapped[list[SiteVersion]] = mapped_column(sa.JSON, default=list, server_default="[]")

    @property
    def origin(self) -> tuple[float, float, float]:
        return (self.origin_x, self.origin_y, self.origin_z)


class Mission(Base):
    __tablename__ = "mission"
    __table_args__ = (
        sa.CheckConstraint(_in("status", MISSION_STATUSES), name="status"),
        sa.UniqueConstraint("site_id", "manifest_sha256"),  # one mission may go into several sites
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    site_id: Mapped[int] = mapped_column(sa.ForeignKey("site.id", ondelete="RESTRICT"), index=True)
    manifest_sha256: Mapped[str] = mapped_column(sa.String(64))
    name: Mapped[str] = mapped_column(sa.Text)
    received_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    status: Mapped[str] = mapped_column(sa.String(16), default="received")
    storage: Mapped[str] = mapped_column(sa.String(16), default="copy")
    root_uri: Mapped[str] = mapped_column(StoreAddress)

    files: Mapped[list[MissionFile]] = relationship(
        back_populates="mission", lazy="raise", cascade="all, delete-orphan"
    )


class MissionFile(Base):
    __tablename__ = "mission_file"
    __table_args__ = (
        sa.UniqueConstraint("mission_id", "path"),
        sa.CheckConstraint(_in("kind", FILE_KINDS), name="kind"),
        sa.CheckConstraint("size_bytes >= 0", name="size"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    mission_id: Mapped[int] = mapped_column(sa.ForeignKey("mission.id", ondelete="CASCADE"), index=True)
    path: Mapped[str] = mapped_column(sa.Text)
    size_bytes: Mapped[int] = mapped_column(sa.BigInteger)
    sha256: Mapped[str] = mapped_column(sa.String(64))
    kind: Mapped[str] = mapped_column(sa.String(16))

    mission: Mapped[Mission] = relationship(back_populates="files", lazy="raise")


class Scene(Base):
    __tablename__ = "scene"
    __table_args__ = (
        sa.UniqueConstraint("site_id", "capture_time"),
        sa.CheckConstraint(_in("status", SCENE_STATUSES), name="status"),
        sa.CheckConstraint("point_count >= 0", name="point_count"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    site_id: Mapped[int] = mapped_column(sa.ForeignKey("site.id", ondelete="RESTRICT"), index=True)
    mission_id: Mapped[int] = mapped_column(sa.ForeignKey("mission.id", ondelete="RESTRICT"), unique=True)
    capture_time: Mapped[datetime] = mapped_column(UTCDateTime)
    point_count: Mapped[int] = mapped_column(sa.BigInteger)
    # {"min": [x, y, z], "max": [x, y, z]} site-local metres
    bounds: Mapped[dict[str, JSON]] = mapped_column(sa.JSON)
    # georegistration (Sim3, residuals) and alignment check against the previous scene
    registration: Mapped[dict[str, JSON]] = mapped_column(sa.JSON, default=dict)
    statistics: Mapped[dict[str, JSON]] = mapped_column(sa.JSON, default=dict)
    tile_store_uri: Mapped[str | None] = mapped_column(StoreAddress, nullable=True)
    status: Mapped[str] = mapped_column(sa.String(16), default="registered")
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)


class Camera(Base):
    __tablename__ = "camera"
    __table_args__ = (
        sa.UniqueConstraint("scene_id", "image_name"),
        sa.CheckConstraint(_in("source", CAMERA_SOURCES), name="source"),
        sa.CheckConstraint("width > 0 AND height > 0", name="size"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    scene_id: Mapped[int] = mapped_column(sa.ForeignKey("scene.id", ondelete="CASCADE"), index=True)
    image_name: Mapped[str] = mapped_column(sa.Text)
    width: Mapped[int] = mapped_column(sa.Integer)
    height: Mapped[int] = mapped_column(sa.Integer)
    fx: Mapped[float] = mapped_column(Float64)
    fy: Mapped[float] = mapped_column(Float64)
    cx: Mapped[float] = mapped_column(Float64)
    cy: Mapped[float] = mapped_column(Float64)
    # cam_from_world: R row-major (9,), t (3,), site-local metres
    rotation: Mapped[list[float]] = mapped_column(sa.JSON)
    translation: Mapped[list[float]] = mapped_column(sa.JSON)
    source: Mapped[str] = mapped_column(sa.String(16))


class LabelSet(Base):
    """One version of a scene's semantic classes. Version 1 is the ingested LAS classification, held
    in the tile store itself (``uri`` NULL); later versions are imported corrections, each a store of
    ``tiles/<tile>/class`` aligned point for point with the tile store (siteline.labelsets)."""

    __tablename__ = "label_set"
    __table_args__ = (
        sa.UniqueConstraint("scene_id", "version"),
        sa.CheckConstraint("version >= 1", name="version"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    scene_id: Mapped[int] = mapped_column(sa.ForeignKey("scene.id", ondelete="CASCADE"), index=True)
    version: Mapped[int] = mapped_column(sa.Integer)
    source: Mapped[str] = mapped_column(sa.Text)
    class_histogram: Mapped[dict[str, int]] = mapped_column(sa.JSON, default=dict)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    uri: Mapped[str | None] = mapped_column(StoreAddress, nullable=True)
    parent_version: Mapped[int | None] = mapped_column(sa.Integer, nullable=True)
    source_sha256: Mapped[str | None] = mapped_column(sa.String(64), nullable=True)
    note: Mapped[str | None] = mapped_column(sa.Text, nullable=True)
    changed_points: Mapped[int | None] = mapped_column(sa.BigInteger, nullable=True)
    # matching statistics and the changed points per (old class, new class)
    details: Mapped[dict[str, JSON] | None] = mapped_column(sa.JSON, nullable=True)


class Pair(Base):
    __tablename__ = "pair"
    __table_args__ = (
        sa.UniqueConstraint("t1_scene_id", "t2_scene_id"),
        sa.CheckConstraint("t1_scene_id <> t2_scene_id", name="distinct_scenes"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    site_id: Mapped[int] = mapped_column(sa.ForeignKey("site.id", ondelete="RESTRICT"), index=True)
    t1_scene_id: Mapped[int] = mapped_column(sa.ForeignKey("scene.id", ondelete="RESTRICT"))
    t2_scene_id: Mapped[int] = mapped_column(sa.ForeignKey("scene.id", ondelete="RESTRICT"))
    radius_m: Mapped[float | None] = mapped_column(Float64, nullable=True)
    parameters: Mapped[dict[str, JSON]] = mapped_column(sa.JSON, default=dict)
    status: Mapped[str] = mapped_column(sa.String(16), default="new")
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)


class View(Base):
    __tablename__ = "view"
    __table_args__ = (sa.UniqueConstraint("pair_id", "param_digest", "index"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    pair_id: Mapped[int] = mapped_column(sa.ForeignKey("pair.id", ondelete="CASCADE"))
    # the pair processing parameters that made this view set (PairParams.digest())
    param_digest: Mapped[str] = mapped_column(sa.String(16))
    index: Mapped[int] = mapped_column(sa.Integer)
    strategy: Mapped[str] = mapped_column(sa.String(64))
    parent_camera_id: Mapped[int | None] = mapped_column(
        sa.ForeignKey("camera.id", ondelete="SET NULL"), nullable=True
    )
    parameters: Mapped[dict[str, JSON]] = mapped_column(sa.JSON, default=dict)
    # full camera (schema/camera.schema.json)
    camera: Mapped[dict[str, JSON]] = mapped_column(sa.JSON)


class Render(Base):
    __tablename__ = "render"
    __table_args__ = (
        sa.UniqueConstraint("view_id", "scene_id", "scale", "point_size_px"),
        sa.CheckConstraint("coverage >= 0 AND coverage <= 1", name="coverage"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    view_id: Mapped[int] = mapped_column(sa.ForeignKey("view.id", ondelete="CASCADE"))
    scene_id: Mapped[int] = mapped_column(sa.ForeignKey("scene.id", ondelete="CASCADE"))
    scale: Mapped[float] = mapped_column(Float64)
    point_size_px: Mapped[int] = mapped_column(sa.Integer)
    coverage: Mapped[float] = mapped_column(Float64)
    change_ratio: Mapped[float | None] = mapped_column(Float64, nullable=True)
    paths: Mapped[dict[str, str]] = mapped_column(StoreAddresses, default=dict)


class Release(Base):
    __tablename__ = "release"
    __table_args__ = (
        sa.UniqueConstraint("name", "version"),
        sa.CheckConstraint(_in("status", RELEASE_STATUSES), name="status"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(sa.String(128))
    version: Mapped[str] = mapped_column(sa.String(32))
    status: Mapped[str] = mapped_column(sa.String(16), default="draft")
    manifest_sha256: Mapped[str | None] = mapped_column(sa.String(64), nullable=True)
    parameters: Mapped[ReleaseRecord] = mapped_column(sa.JSON, default=dict)
    root_uri: Mapped[str | None] = mapped_column(StoreAddress, nullable=True)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    published_at: Mapped[datetime | None] = mapped_column(UTCDateTime, nullable=True)


class ReleaseItem(Base):
    __tablename__ = "release_item"
    __table_args__ = (
        sa.UniqueConstraint("release_id", "item_id"),
        sa.CheckConstraint(_in("split", SPLITS), name="split"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    release_id: Mapped[int] = mapped_column(sa.ForeignKey("release.id", ondelete="CASCADE"), index=True)
    item_id: Mapped[str] = mapped_column(sa.String(128))
    pair_id: Mapped[int] = mapped_column(sa.ForeignKey("pair.id", ondelete="RESTRICT"))
    view_id: Mapped[int | None] = mapped_column(sa.ForeignKey("view.id", ondelete="SET NULL"), nullable=True)
    split: Mapped[str] = mapped_column(sa.String(8))
    coverage: Mapped[float] = mapped_column(Float64)
    change_ratio: Mapped[float] = mapped_column(Float64)
    # the share of its changed pixels whose colour differs between A and B; None: nothing changed, or
    # built before it was measured (siteline.pairs.render.change_visibility)
    change_visible: Mapped[float | None] = mapped_column(Float64, nullable=True)
    files: Mapped[dict[str, str]] = mapped_column(sa.JSON, default=dict)


class StageRun(Base):
    """One execution of a pipeline stage on a subject (``mission:<sha>``, ``scene:<id>``, ...)."""

    __tablename__ = "stage_run"
    __table_args__ = (
        sa.CheckConstraint(_in("status", STAGE_STATUSES), name="status"),
        sa.Index("ix_stage_run_subject", "stage", "subject"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    stage: Mapped[str] = mapped_column(sa.String(64))
    subject: Mapped[str] = mapped_column(sa.String(256))
    parameters: Mapped[dict[str, JSON]] = mapped_column(sa.JSON, default=dict)
    status: Mapped[str] = mapped_column(sa.String(16), default="running")
    started_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    finished_at: Mapped[datetime | None] = mapped_column(UTCDateTime, nullable=True)
    error_text: Mapped[str | None] = mapped_column(sa.Text, nullable=True)
    orchestrator_run_id: Mapped[str | None] = mapped_column(sa.String(64), nullable=True)
