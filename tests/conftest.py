"""Shared fixtures: catalogs on SQLite and PostgreSQL, a SITELINE_HOME per test."""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from siteline.catalog.context import StageContext
from siteline.pointpass import TilingResources

PG_ADMIN_URL = os.environ.get(
    "SITELINE_TEST_POSTGRES_URL", "postgresql+psycopg://postgres@127.0.0.1:5432/postgres"
)
REPO = Path(__file__).resolve().parents[1]


def pytest_configure(config: pytest.Config) -> None:
    """Under pytest-xdist (``make test`` runs a worker a core), each worker and the processes it starts
    get their share of the cores for torch's and OpenMP's threads (unless OMP_NUM_THREADS says): two
    workers of two threads each on two cores spin against each other (a render test took 4x as long)."""
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "0"))
    if workers > 1 and "OMP_NUM_THREADS" not in os.environ:
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
        os.environ["OMP_NUM_THREADS"] = str(max(1, cores // workers))


@pytest.fixture(scope="session")
def pg_admin() -> Iterator:
    import sqlalchemy as sa

    engine = sa.create_engine(PG_ADMIN_URL, isolation_level="AUTOCOMMIT")
    try:
        with engine.connect() as conn:
            conn.execute(sa.text("SELECT 1"))
    except sa.exc.OperationalError as exc:
        pytest.fail(
            f"PostgreSQL is not reachable at {PG_ADMIN_URL} ({exc.orig}); start it "
            "(`pg_ctlcluster --skip-systemctl-redirect $(ls /etc/postgresql) main start`) or set "
            "SITELINE_TEST_POSTGRES_URL."
        )
    yield engine
    engine.dispose()


def _pg_database(pg_admin) -> Iterator[str]:
    import sqlalchemy as sa

    name = f"siteline_test_{uuid.uuid4().hex[:12]}"
    with pg_admin.connect() as conn:
        conn.execute(sa.text(f'CREATE DATABASE "{name}"'))
    url = pg_admin.url.set(database=name).render_as_string(hide_password=False)
    try:
        yield url
    finally:
        with pg_admin.connect() as conn:
            conn.execute(sa.text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))


@pytest.fixture
def postgres_url(pg_admin) -> Iterator[str]:
    """URL of a fresh PostgreSQL database with a random name, dropped after the test."""
    yield from _pg_database(pg_admin)


@pytest.fixture
def sqlite_url(tmp_path: Path) -> str:
    return f"sqlite:///{tmp_path / 'catalog.sqlite'}"


@pytest.fixture(params=["sqlite", "postgresql"])
def db_url(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[str]:
    """An empty catalog database URL, once on SQLite and once on PostgreSQL."""
    if request.param == "sqlite":
        yield f"sqlite:///{tmp_path / 'catalog.sqlite'}"
    else:
        yield from _pg_database(request.getfixturevalue("pg_admin"))


@pytest.fixture
def migrated_url(db_url: str) -> str:
    from siteline.catalog import migrate
    from siteline.catalog.engine import make_engine

    engine = make_engine(db_url)
    migrate.upgrade(engine)
    engine.dispose()
    return db_url


@pytest.fixture
def home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A fresh SITELINE_HOME (SQLite catalog inside) for CLI tests."""
    h = tmp_path / "home"
    monkeypatch.setenv("SITELINE_HOME", str(h))
    monkeypatch.delenv("SITELINE_DATABASE_URL", raising=False)
    return h


@pytest.fixture(scope="session")
def synth_site(tmp_path_factory) -> Path:
    """A small synthetic site (3 epochs, ~70k points each, photos, COLMAP), generated once per run."""
    from sitehelpers import SYNTH

    from siteline.synth import write_site

    out = tmp_path_factory.mktemp("synth-site")
    write_site(out, SYNTH)
    return out


@pytest.fixture(scope="session")
def s3_endpoint() -> Iterator[str]:
    """A local S3 server (moto) on 127.0.0.1: the object store that "other machines" share. fsspec's
    configuration points s3:// at it, in this process and (through FSSPEC_S3) in any child."""
    import json
    import logging

    import fsspec
    from moto.server import ThreadedMotoServer

    logging.getLogger("werkzeug").setLevel(logging.ERROR)
    server = ThreadedMotoServer(ip_address="127.0.0.1", port=0, verbose=False)
    server.start()
    host, port = server.get_host_and_port()
    endpoint = f"http://{host}:{port}"
    conf = {"endpoint_url": endpoint, "key": "siteline-test", "secret": "siteline-test"}
    saved = (fsspec.config.conf.get("s3"), os.environ.get("FSSPEC_S3"))
    fsspec.config.conf["s3"] = conf
    os.environ["FSSPEC_S3"] = json.dumps(conf)
    try:
        yield endpoint
    finally:
        server.stop()
        if saved[0] is None:
            fsspec.config.conf.pop("s3", None)
        else:
            fsspec.config.conf["s3"] = saved[0]
        if saved[1] is None:
            os.environ.pop("FSSPEC_S3", None)
        else:
            os.environ["FSSPEC_S3"] = saved[1]


@pytest.fixture
def s3_store(s3_endpoint: str) -> str:
    """``s3://<fresh bucket>/stores`` on the local S3 server."""
    import fsspec

    bucket = f"siteline-{uuid.uuid4().hex[:12]}"
    fsspec.filesystem("s3").mkdir(bucket)
    return f"s3://{bucket}/stores"


@pytest.fixture(scope="session")
def scenes(tmp_path_factory, synth_site):
    """(settings, catalog) of a home with the first two epochs of ``synth_site`` ingested and tiled
    (scenes 1 and 2, pair 1). Tests may add label-set versions and pair outputs, never remove them."""
    from sitehelpers import epoch_dirs, make_home

    from siteline.catalog import open_catalog
    from siteline.ingest.stage import ingest_mission
    from siteline.tiles.stage import tile_scene

    settings = make_home(tmp_path_factory.mktemp("scenes"), site_dir=synth_site)
    cat = open_catalog(settings)
    for m in epoch_dirs(synth_site)[:2]:
        r = ingest_mission(StageContext(cat, settings), m, "demo")
        tile_scene(StageContext(cat, settings), r.scene_id, resources=TilingResources(workers=1))
    yield settings, cat
    cat.dispose()
