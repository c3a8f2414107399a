"""The one configuration object: every setting, its default and its unit.

Environment variables (read here and nowhere else):

- ``SITELINE_HOME``: folder holding the SQLite catalog and the data stores (default ``~/.siteline``).
- ``SITELINE_DATABASE_URL``: SQLAlchemy URL of the catalog; overrides the SQLite file in the home,
  e.g. ``postgresql+psycopg://postgres@127.0.0.1:5432/siteline`` for shared use.
- ``SITELINE_STORE_URL``: root of the data stores, a local folder or an fsspec URL such as
  ``s3://bucket/siteline`` that workers on several machines share (default ``$SITELINE_HOME/stores``).
  The file system's endpoint and credentials come from fsspec's configuration (e.g.
  ``FSSPEC_S3='{"endpoint_url": "http://127.0.0.1:9000", "key": "...", "secret": "..."}'``).
- ``SITELINE_TASK_RUNNER``: the flows' task runner: ``threads`` (default), ``processes`` or ``dask``;
  ``SITELINE_TASK_WORKERS`` its workers (default 2); ``SITELINE_DASK_ADDRESS`` a running Dask
  scheduler (``tcp://host:8786``; default: a LocalCluster on 127.0.0.1).
- ``SITELINE_RELEASE_POLICY``: ``on-demand`` (default) or ``every-pair`` (the flows build a release
  after every processed pair); ``SITELINE_RELEASE_NAME`` that release's name (default ``<site>-cd``).
- ``SITELINE_TILE_BATCH_POINTS``: a tile of more points is levelled and written a batch of its
  blocks at a time (through a scratch copy of the tile), so a tiling worker holds about 200 bytes x
  this many points whatever the density (default 1,000,000: a worker peaks near 0.5 GB, most of
  it the read pass; 4,000,000: ~1 GB, and no faster on the bench). The store is the same at any
  value (siteline.tiles.batches; docs/performance.md).
- ``SITELINE_PREVIEW_URL``: where ``siteline previews serve`` answers (default
  ``http://127.0.0.1:4201``); the flows' image artifacts point there.
- ``SITELINE_CATALOG_WAIT_S``: how long a writer waits for a SQLite catalog another writer holds
  (default 30 s; siteline.catalog.engine), then stops with one line and exit status 1.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from siteline.errors import ConfigError
from siteline.stores import Store, layout, open_store

CATALOG_FILENAME = "catalog.sqlite"
DEFAULT_TILE_BATCH_POINTS = 1_000_000
TASK_RUNNERS = ("threads", "processes", "dask")
RELEASE_POLICIES = ("every-pair", "on-demand")
# where `siteline previews serve` (started by `make serve`) answers: the Prefect UI loads images from it
DEFAULT_PREVIEW_URL = "http://127.0.0.1:4201"


@dataclass(frozen=True)
class Settings:
    """Where siteline keeps its catalog and stores.

    home: folder for the default SQLite catalog, releases, and local staging and caches.
    database_url: SQLAlchemy URL of the catalog.
    store_url: root of the data stores (mission blobs, tiles, labels, renders): a local folder or an
    fsspec URL; empty means ``home/stores``.
    """

    home: Path
    database_url: str
    store_url: str = ""
    task_runner: str = "threads"
    task_workers: int = 2
    dask_address: str = ""
    release_policy: str = "on-demand"
    release_name: str = ""
    preview_url: str = DEFAULT_PREVIEW_URL
    tile_batch_points: int = DEFAULT_TILE_BATCH_POINTS

    @property
    def store(self) -> Store:
        """The data stores; folders for remote stores are built under ``home/staging`` first."""
        return open_store(self.store_url or str(layout.default_store(self.home)), layout.staging(self.home))

    @property
    def is_sqlite(self) -> bool:
        return self.database_url.startswith("sqlite")


def sqlite_url(path: Path) -> str:
    """SQLAlchemy URL of a SQLite file at ``path``."""
    return f"sqlite:///{path}"


def load_settings(environ: dict[str, str] | None = None) -> Settings:
    """Settings from the environment (``os.environ`` unless ``environ`` is given)."""
    env = os.environ if environ is None else environ
    raw_home = env.get("SITELINE_HOME", "").strip()
    home = Path(raw_home).expanduser() if raw_home else Path.home() / ".siteline"
    if home.exists() and not home.is_dir():
        raise ConfigError(f"SITELINE_HOME={home} exists and is not a folder: point it at a folder.")
    url = env.get("SITELINE_DATABASE_URL", "").strip()
    if not url:
        url = sqlite_url(home.resolve() / CATALOG_FILENAME)
    elif "://" not in url:
        raise ConfigError(
            f"SITELINE_DATABASE_URL={url!r} is not a database URL: use e.g. "
            "'postgresql+psycopg://postgres@127.0.0.1:5432/siteline' or 'sqlite:////path/catalog.sqlite'."
        )
    store = env.get("SITELINE_STORE_URL", "").strip()
    if store.startswith("file://"):
        store = store[len("file://") :]
    if store and "://" not in store:
        store = str(Path(store).expanduser().resolve())
    runner = env.get("SITELINE_TASK_RUNNER", "threads").strip().lower() or "threads"
    if runner not in TASK_RUNNERS:
        raise ConfigError(f"SITELINE_TASK_RUNNER={runner!r}: use one of {', '.join(TASK_RUNNERS)}.")
    raw_workers = env.get("SITELINE_TASK_WORKERS", "2").strip() or "2"
    if not raw_workers.isdigit() or int(raw_workers) < 1:
        raise ConfigError(f"SITELINE_TASK_WORKERS={raw_workers!r} must be a positive whole number.")
    raw_batch = env.get("SITELINE_TILE_BATCH_POINTS", "").strip().replace("_", "") or str(
        DEFAULT_TILE_BATCH_POINTS
    )
    if not raw_batch.isdigit() or int(raw_batch) < 1:
        raise ConfigError(
            f"SITELINE_TILE_BATCH_POINTS={raw_batch!r} must be a positive whole number of points."
        )
    policy = env.get("SITELINE_RELEASE_POLICY", "on-demand").strip() or "on-demand"
    if policy not in RELEASE_POLICIES:
        raise ConfigError(f"SITELINE_RELEASE_POLICY={policy!r}: use one of {', '.join(RELEASE_POLICIES)}.")
    return Settings(
        home=home.resolve(),
        database_url=url,
        store_url=store,
        task_runner=runner,
        task_workers=int(raw_workers),
        dask_address=env.get("SITELINE_DASK_ADDRESS", "").strip(),
        release_policy=policy,
        release_name=env.get("SITELINE_RELEASE_NAME", "").strip(),
        preview_url=(env.get("SITELINE_PREVIEW_URL", "").strip() or DEFAULT_PREVIEW_URL).rstrip("/"),
        tile_batch_points=int(raw_batch),
    )
