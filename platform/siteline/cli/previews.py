"""``siteline previews serve``: the read-only HTTP route the Prefect UI loads images from."""

from __future__ import annotations

from urllib.parse import urlsplit

import typer

from siteline.cli.common import console, settings
from siteline.errors import ConfigError

app = typer.Typer(help="Previews of pairs and releases for the Prefect UI.", no_args_is_help=True)


@app.command("serve")
def serve(
    host: str | None = typer.Option(None, "--host", help="Address to listen on (default: SITELINE_PREVIEW_URL's)."),
    port: int | None = typer.Option(None, "--port", help="Port (default: SITELINE_PREVIEW_URL's, 4201)."),
) -> None:
    """Serve SITELINE_HOME's pair previews and published releases, read-only, until interrupted."""
    from siteline.previews.server import make_server

    cfg = settings()
    url = urlsplit(cfg.preview_url)
    bind = (host or url.hostname or "127.0.0.1", port or url.port or 4201)
    try:
        server = make_server(cfg.home, *bind)
    except OSError as exc:
        raise ConfigError(f"cannot serve previews on {bind[0]}:{bind[1]}: {exc.strerror or exc}") from exc
    console.print(f"serving previews and published releases of {cfg.home} at http://{bind[0]}:{bind[1]}/ (read-only)")
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        server.server_close()
