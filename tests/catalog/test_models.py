"""Catalog invariants on both SQLite and PostgreSQL."""

from __future__ import annotations

from datetime import UTC, datetime

import pytest
import sqlalchemy as sa

from siteline.catalog import open_catalog
from siteline.catalog.models import Mission, Release, ReleaseItem, Scene, Site, StageRun
from siteline.catalog.sites import add_site, get_site
from siteline.errors import ImmutableError, SiteError, SiteNotFoundError
from siteline.site.spec import make_site_spec

T0 = datetime(2024, 11, 27, 15, 0, tzinfo=UTC)


@pytest.fixture
def cat(migrated_url: str):
    c = open_catalog(migrated_url)
    yield c
    c.dispose()


def _site(session, name="s") -> Site:
    return add_site(session, make_site_spec(name, "EPSG:32618", (445000.123456789, 5030000.987654321, 80.5)))


def _mission(session, site: Site, sha: str) -> Mission:
    m = Mission(site_id=site.id, manifest_sha256=sha, name=f"m-{sha[:4]}", root_uri="/x")
    session.add(m)
    session.flush()
    return m


def _scene(session, site: Site, mission: Mission, t: datetime) -> Scene:
    s = Scene(
        site_id=site.id,
        mission_id=mission.id,
        capture_time=t,
        point_count=10,
        bounds={"min": [0, 0, 0], "max": [1, 1, 1]},
    )
    session.add(s)
    session.flush()
    return s


def test_site_round_trips_float64_origin_and_taxonomy(cat) -> None:
    with cat.transaction() as s:
        _site(s)
    with cat.transaction() as s:
        site = get_site(s, "s")
        assert site.spec.origin == (445000.123456789, 5030000.987654321, 80.5)
        assert site.spec.taxonomy.id_of("crane") == 3
        assert site.created_at is not None and site.created_at.tzinfo is not None


def test_duplicate_site_name_is_refused_and_nothing_written(cat) -> None:
    with cat.transaction() as s:
        _site(s)
    with pytest.raises(SiteError, match="already exists"), cat.transaction() as s:
        _site(s)
    with cat.transaction() as s:
        assert s.execute(sa.select(sa.func.count(Site.id))).scalar_one() == 1


def test_unknown_site_names_known_ones(cat) -> None:
    with cat.transaction() as s:
        _site(s, "alpha")
    with pytest.raises(SiteNotFoundError, match="alpha"), cat.transaction() as s:
        get_site(s, "beta")


def test_mission_manifest_hash_is_unique(cat) -> None:
    with cat.transaction() as s:
        site = _site(s)
        _mission(s, site, "a" * 64)
    with pytest.raises(sa.exc.IntegrityError), cat.transaction() as s:
        _mission(s, s.get(Site, site.id), "a" * 64)


def test_one_scene_per_site_and_capture_time(cat) -> None:
    with cat.transaction() as s:
        site = _site(s)
        _scene(s, site, _mission(s, site, "a" * 64), T0)
    with pytest.raises(sa.exc.IntegrityError), cat.transaction() as s:
        site = s.get(Site, site.id)
        _scene(s, site, _mission(s, site, "b" * 64), T0)


def test_release_name_version_unique(cat) -> None:
    with cat.transaction() as s:
        s.add(Release(name="r", version="1.0.0"))
    with pytest.raises(sa.exc.IntegrityError), cat.transaction() as s:
        s.add(Release(name="r", version="1.0.0"))


def test_naive_timestamp_is_refused(cat) -> None:
    with pytest.raises(sa.exc.StatementError, match="no timezone"), cat.transaction() as s:
        s.add(StageRun(stage="ingest", subject="x", started_at=datetime(2025, 1, 1)))
        s.flush()


def test_published_release_cannot_be_modified(cat) -> None:
    with cat.transaction() as s:
        site = _site(s)
        sc1 = _scene(s, site, _mission(s, site, "a" * 64), T0)
        sc2 = _scene(s, site, _mission(s, site, "b" * 64), T0.replace(day=28))
        from siteline.catalog.models import Pair

        pair = Pair(site_id=site.id, t1_scene_id=sc1.id, t2_scene_id=sc2.id)
        s.add(pair)
        s.flush()
        rel = Release(name="r", version="1.0.0")
        s.add(rel)
        s.flush()
        s.add(
            ReleaseItem(
                release_id=rel.id,
                item_id="v0",
                pair_id=pair.id,
                split="train",
                coverage=1.0,
                change_ratio=0.1,
            )
        )
        pair_id, rel_id = pair.id, rel.id
    # a draft can still change; publishing is the last change allowed
    with cat.transaction() as s:
        rel = s.get(Release, rel_id)
        rel.parameters = {"scale": 0.125}
        rel.status = "published"
        rel.published_at = datetime.now(UTC)
    with pytest.raises(ImmutableError, match="published"), cat.transaction() as s:
        s.get(Release, rel_id).parameters = {"scale": 1}
    with pytest.raises(ImmutableError), cat.transaction() as s:
        s.delete(s.get(Release, rel_id))
    with pytest.raises(ImmutableError), cat.transaction() as s:
        s.add(
            ReleaseItem(
                release_id=rel_id, item_id="v1", pair_id=pair_id, split="test", coverage=1.0, change_ratio=0.0
            )
        )
    with pytest.raises(ImmutableError), cat.transaction() as s:
        item = s.execute(sa.select(ReleaseItem)).scalar_one()
        item.split = "val"
    with cat.transaction() as s:
        rel = s.get(Release, rel_id)
        assert rel.parameters == {"scale": 0.125}
        assert s.execute(sa.select(sa.func.count(ReleaseItem.id))).scalar_one() == 1


def test_pair_refuses_same_scene_twice(cat) -> None:
    from siteline.catalog.models import Pair

    with cat.transaction() as s:
        site = _site(s)
        sc = _scene(s, site, _mission(s, site, "a" * 64), T0)
    with pytest.raises(sa.exc.IntegrityError), cat.transaction() as s:
        s.add(Pair(site_id=site.id, t1_scene_id=sc.id, t2_scene_id=sc.id))


def test_label_set_versions_are_unique_and_newest_is_found(cat) -> None:
    from siteline.catalog.labelsets import label_set, newest_versions, record_label_set
    from siteline.catalog.models import LabelSet
    from siteline.errors import LabelSetError
    from siteline.records import LabelSetImport, StageRun

    def imported(scene_id: int, uri: str, file: str, sha: str, note: str | None, changed: int, changes: dict):
        return LabelSetImport(
            scene_id, 2, 1, uri, file, sha, 10, 10, 0, 0, 0, changed, changes, {}, note=note
        )

    with cat.transaction() as s:
        site = _site(s)
        scene = _scene(s, site, _mission(s, site, "a" * 64), T0)
        s.add(LabelSet(scene_id=scene.id, version=1, source="las", class_histogram={"ground": 10}))
        s.flush()
        record_label_set(
            s,
            imported(scene.id, "/x/v2.zarr", "f.laz", "b" * 64, "fix", 1, {"ground->building": 1}),
            StageRun("t", "x"),
        )
        sid = scene.id
    with cat.transaction() as s:
        assert newest_versions(s, [sid]) == {sid: 2}
        row = label_set(s, sid)
        assert (row.version, row.parent_version, row.changed_points, row.note) == (2, 1, 1, "fix")
        assert row.details["changes"] == {"ground->building": 1} and label_set(s, sid, 1).uri is None
        with pytest.raises(LabelSetError, match="no label-set version 3"):
            label_set(s, sid, 3)
    with pytest.raises(sa.exc.IntegrityError), cat.transaction() as s:
        record_label_set(
            s, imported(sid, "/x/again.zarr", "g.laz", "c" * 64, None, 0, {}), StageRun("t", "x")
        )
