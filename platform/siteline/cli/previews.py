"""``siteline previews serve``: the read-only HTTP server the Prefect UI loads images from, with the
release browser and the 3D pair viewer."""

from __future__ import annotations

from pathlib import Path
from urllib.parse import urlsplit

import typer

from siteline.cli.common import catalog, console, settings
from siteline.errors import ConfigError

app = typer.Typer(help="Previews of pairs and releases for the Prefect UI.", no_args_is_help=True)


def _loopback(host: str) -> bool:
    import ipaddress

    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _bind(preview_url: str, host: str | None, port: int | None, public: bool) -> tuple[str, int]:
    """The address to listen on: ``--host`` / ``--port``, else SITELINE_PREVIEW_URL's, else
    127.0.0.1:4201. ConfigError (one line, exit 2) for a port out of range, a URL whose port is not a
    number, or an address beyond loopback without ``--public``."""
    url = urlsplit(preview_url)
    try:
        url_port = url.port
    except ValueError as exc:
        raise ConfigError(
            f"SITELINE_PREVIEW_URL {preview_url!r} has no valid port ({exc}); give one such as http://127.0.0.1:4201."
        ) from exc
    chosen = port if port is not None else (url_port if url_port is not None else 4201)
    if not 1 <= chosen <= 65535:
        raise ConfigError(f"port {chosen}: give one from 1 to 65535 (--port or SITELINE_PREVIEW_URL).")
    address = host or url.hostname or "127.0.0.1"
    if not _loopback(address) and not public:
        raise ConfigError(
            f"{address} is an address beyond this machine and the preview server has no authentication: "
            "pass --public to serve every release of this home there, or listen on 127.0.0.1."
        )
    return address, chosen


@app.command("serve")
def serve(
    host: str | None = typer.Option(
        None, "--host", help="Address to listen on (default: SITELINE_PREVIEW_URL's)."
    ),
    port: int | None = typer.Option(None, "--port", help="Port (default: SITELINE_PREVIEW_URL's, 4201)."),
    public: bool = typer.Option(
        False, "--public", help="Allow an address beyond this machine (the server has no authentication)."
    ),
) -> None:
    """Serve SITELINE_HOME's pair previews and published releases, the release browser
    (/browse/NAME/VERSION/, drafts too) and the 3D pair viewer (/3d/NAME/VERSION/PAIR/), read-only,
    until interrupted."""
    from siteline.catalog.releases import release_location
    from siteline.pipeline import pair_cloud
    from siteline.previews.server import ReleaseAccess, make_server

    cfg = settings()
    bind = _bind(cfg.preview_url, host, port, public)
    with catalog() as cat:

        def locate(name: str, version: str) -> tuple[Path, str]:  # NotFoundError is a LookupError
            with cat.transaction() as s:
                return release_location(s, name, version)

        access = ReleaseAccess(locate, lambda doc, pair: pair_cloud(cat, cfg, doc, pair))
        try:
            server = make_server(cfg.home, *bind, access=access)
        except OSError as exc:
            raise ConfigError(f"cannot serve previews on {bind[0]}:{bind[1]}: {exc.strerror or exc}") from exc
        if not _loopback(bind[0]):
            console.print(
                f"warning: listening on {bind[0]}, beyond this machine: anyone who reaches port {bind[1]} reads "
                f"every release and preview of {cfg.home}, with no authentication."
            )
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
