"""``siteline previews serve``: the read-only HTTP server the Prefect UI loads images from, with the
release browser and the 3D pair viewer."""

from __future__ import annotations

from pathlib import Path
from urllib.parse import urlsplit

import typer

from siteline.cli.common import catalog, console, settings
from siteline.errors import ConfigError

app = typer.Typer(help="Previews of pairs and releases for the Prefect UI.", no_args_is_help=True)


@app.command("serve")
def serve(
    host: str | None = typer.Option(None, "--host", help="Address to listen on (default: SITELINE_PREVIEW_URL's)."),
    port: int | None = typer.Option(None, "--port", help="Port (default: SITELINE_PREVIEW_URL's, 4201)."),
) -> None:
    """Serve SITELINE_HOME's pair previews and published releases, the release browser
    (/browse/NAME/VERSION/, drafts too) and the 3D pair viewer (/3d/NAME/VERSION/PAIR/), read-only,
    until interrupted."""
    from siteline.catalog.releases import release_location
    from siteline.pipeline import pair_cloud
    from siteline.previews.server import ReleaseAccess, make_server

    cfg = settings()
    url = urlsplit(cfg.preview_url)
    bind = (host or url.hostname or "127.0.0.1", port or url.port or 4201)
    with catalog() as cat:

        def locate(name: str, version: str) -> tuple[Path, str]:  # NotFoundError is a LookupError
            with cat.transaction() as s:
                return release_location(s, name, version)

        access = ReleaseAccess(locate, lambda doc, pair: pair_cloud(cat, cfg, doc, pair))
        try:
            server = make_server(cfg.home, *bind, access=access)
        except OSError as exc:
            raise ConfigError(f"cannot serve previews on {bind[0]}:{bind[1]}: {exc.strerror or exc}") from exc
        console.print(
            f"serving previews and releases of {cfg.home} at http://{bind[0]}:{bind[1]}/ (read-only): "
            "the release browser at /browse/NAME/VERSION/, pairs in 3D at /3d/NAME/VERSION/PAIR/"
        )
        try:
            server.serve_forever()
        except KeyboardInterrupt:
            pass
        finally:
            server.server_close()
