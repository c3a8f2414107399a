"""``siteline demo``: the whole pipeline on the embedded default (SQLite, local files, a generated site)."""

from __future__ import annotations

import typer

from siteline.catalog import migrate, open_catalog
from siteline.catalog.engine import make_engine
from siteline.catalog.sites import add_site, get_site, scene_count
from siteline.cli.common import console, print_record, settings
from siteline.cli.site import site_record
from siteline.errors import SiteNotFoundError
from siteline.site import make_site_spec

DEMO_SITE = "demo"
DEMO_ORIGIN = (445_000.0, 5_030_000.0, 80.0)
# site-local metres: a 120 m x 90 m construction site
DEMO_FENCE_M = [(-60.0, -45.0), (60.0, -45.0), (60.0, 45.0), (-60.0, 45.0), (-60.0, -45.0)]


def demo(site_name: str = typer.Option(DEMO_SITE, "--site", help="Name of the demo site.")) -> None:
    """Initialise SITELINE_HOME, migrate the catalog, create the demo site and show it."""
    cfg = settings()
    cfg.home.mkdir(parents=True, exist_ok=True)
    cfg.store_dir.mkdir(parents=True, exist_ok=True)
    console.rule("1. catalog")
    engine = make_engine(cfg.database_url)
    migrate.upgrade(engine)
    engine.dispose()
    console.print(f"home {cfg.home}; catalog at revision {migrate.head_revision()}")
    cat = open_catalog(cfg)
    try:
        console.rule("2. site")
        with cat.transaction() as s:
            try:
                site = get_site(s, site_name)
                console.print(f"site {site_name} already exists: reusing it")
            except SiteNotFoundError:
                site = add_site(s, make_site_spec(site_name, "EPSG:32618", DEMO_ORIGIN, DEMO_FENCE_M))
            record = site_record(site, scene_count(s, site))
        print_record(f"site {site_name}", record)
    finally:
        cat.dispose()
