"""The one configuration object: every setting, its default and its unit.

Environment variables (read here and nowhere else):

- ``SITELINE_HOME``: folder holding the SQLite catalog and the data stores (default ``~/.siteline``).
- ``SITELINE_DATABASE_URL``: SQLAlchemy URL of the catalog; overrides the SQLite file in the home,
  e.g. ``postgresql+psycopg://postgres@127.0.0.1:5432/siteline`` for shared use.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from siteline.errors import ConfigError

CATALOG_FILENAME = "catalog.sqlite"


@dataclass(frozen=True)
class Settings:
    """Where siteline keeps its catalog and stores.

    home: folder for the default SQLite catalog and the data stores.
    database_url: SQLAlchemy URL of the catalog.
    """

    home: Path
    database_url: str

    @property
    def store_dir(self) -> Path:
        """Content-addressed mission files and tile stores live under here."""
        return self.home / "stores"

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
    return Settings(home=home.resolve(), database_url=url)
