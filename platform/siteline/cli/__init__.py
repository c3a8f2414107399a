"""The ``siteline`` command line. Every command has ``--help``; list/show commands take ``--json``."""

from __future__ import annotations

import sys

import typer

from siteline import __version__
from siteline.cli import bench, db, demo, ingest, release, render, site, synth, watch
from siteline.cli.common import err_console
from siteline.errors import SitelineError

app = typer.Typer(
    name="siteline",
    help="Drone surveys of construction sites turned into change-detection datasets.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)
app.command("init")(db.init)
app.command("demo")(demo.demo)
app.add_typer(db.app, name="db")
app.add_typer(site.app, name="site")
app.command("render")(render.render)
app.add_typer(render.views_app, name="views")
app.add_typer(synth.app, name="synth")
app.command("ingest")(ingest.ingest)
app.add_typer(ingest.mission_app, name="mission")
app.add_typer(ingest.scene_app, name="scene")
app.add_typer(ingest.photo_app, name="photo")
app.add_typer(release.app, name="release")
app.command("train")(release.train_cmd)
app.command("evaluate")(release.evaluate_cmd)
app.command("watch")(watch.watch)
app.add_typer(bench.app, name="bench")


@app.callback()
def _root(version: bool = typer.Option(False, "--version", help="Print the version and exit.")) -> None:
    if version:
        typer.echo(__version__)
        raise typer.Exit()


def main(argv: list[str] | None = None) -> int:
    """Entry point: run the CLI; siteline errors print one clear line and exit with status 2."""
    try:
        app(args=argv, standalone_mode=False)
    except SitelineError as exc:
        err_console.print(f"[bold red]error:[/] {exc}", highlight=False, soft_wrap=True)
        return 2
    except typer.Exit as exc:
        return exc.exit_code
    except typer.Abort:
        err_console.print("aborted")
        return 1
    except Exception as exc:  # click usage errors
        import click

        if isinstance(exc, click.ClickException):
            exc.show()
            return exc.exit_code
        raise
    return 0


if __name__ == "__main__":
    sys.exit(main())
