"""The CLI: init, db, site create/list/show, JSON output parsed back, clear errors, no rows on error."""

from __future__ import annotations

import json

import pytest
import sqlalchemy as sa
from sitehelpers import cli_create_site, run_cli

run = run_cli


@pytest.fixture
def initialised(home, capsys):
    assert run(capsys, "init")[0] == 0
    return home


def _every_command() -> list[list[str]]:
    """The argv of every command and group of the CLI, found by walking its click tree."""
    import typer

    from siteline.cli import app

    out: list[list[str]] = []

    def walk(cmd, path: list[str]) -> None:  # noqa: ANN001
        out.append(path)
        for name, sub in sorted(getattr(cmd, "commands", {}).items()):
            walk(sub, [*path, name])

    walk(typer.main.get_command(app), [])
    return out


def test_every_command_has_help(capsys) -> None:
    commands = _every_command()
    assert len(commands) > 35 and ["release", "export"] in commands and ["release", "score"] in commands
    for argv in commands:
        code, out, _ = run(capsys, *argv, "--help")
        assert code == 0 and "Usage" in out, argv
        usage = " ".join(out.split()).split("Usage: ", 1)[1]
        # the help of that command, whatever the program is called (`pytest`, `python -m pytest`)
        assert usage.split("[OPTIONS]", 1)[0].rstrip().endswith(" ".join(argv)), argv


def test_site_create_list_show_json(initialised, capsys, tmp_path) -> None:
    fence = tmp_path / "fence.geojson"
    fence.write_text(
        json.dumps(
            {
                "type": "Polygon",
                "coordinates": [[[445000, 5030000], [445100, 5030000], [445100, 5030080], [445000, 5030000]]],
            }
        )
    )
    code, out, err = cli_create_site(capsys, fence, "--json")
    assert code == 0, err
    created = json.loads(out)
    assert created["origin"] == [445000.0, 5030000.0, 80.0]
    assert created["fence_area_m2"] == pytest.approx(4000.0)
    code, out, _ = run(capsys, "site", "list", "--json")
    assert [s["name"] for s in json.loads(out)] == ["demo"]
    code, out, _ = run(capsys, "site", "show", "demo", "--json")
    shown = json.loads(out)
    assert shown["crs"] == "EPSG:32618" and shown["scenes"] == 0 and shown["classes"]["ground"] == 1
    code, out, _ = run(capsys, "site", "show", "demo")
    assert "demo" in out and "EPSG:32618" in out


def _site_count(home) -> int:
    engine = sa.create_engine(f"sqlite:///{home / 'catalog.sqlite'}")
    with engine.connect() as c:
        n = c.execute(sa.text("SELECT count(*) FROM site")).scalar()
    engine.dispose()
    return n


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--crs", "EPSG:123456789", "--origin", "0", "0", "0"], "not known"),
        (["--crs", "garbage", "--origin", "0", "0", "0"], "not known"),
        (["--crs", "EPSG:32618", "--origin", "nan", "0", "0"], "not finite"),
        (["--crs", "EPSG:32618", "--origin", "0", "inf", "0"], "not finite"),
    ],
)
def test_bad_site_input_is_refused_without_rows(initialised, capsys, args, message) -> None:
    code, out, err = run(capsys, "site", "create", "bad", *args)
    assert code == 2
    assert message in err
    assert _site_count(initialised) == 0


def test_bad_fence_and_taxonomy_files_are_named(initialised, capsys, tmp_path) -> None:
    fence = tmp_path / "open.geojson"
    fence.write_text(json.dumps({"type": "Polygon", "coordinates": [[[0, 0], [1, 0], [1, 1], [0, 1]]]}))
    code, _, err = run(
        capsys, "site", "create", "x", "--crs", "EPSG:32618", "--origin", "0", "0", "0", "--fence", str(fence)
    )
    assert code == 2 and "open.geojson" in err and "not closed" in err
    tax = tmp_path / "tax.json"
    tax.write_text(json.dumps({"name": "t", "classes": "nope"}))
    code, _, err = run(
        capsys,
        "site",
        "create",
        "x",
        "--crs",
        "EPSG:32618",
        "--origin",
        "0",
        "0",
        "0",
        "--taxonomy",
        str(tax),
    )
    assert code == 2 and "tax.json" in err
    code, _, err = run(
        capsys,
        "site",
        "create",
        "x",
        "--crs",
        "EPSG:32618",
        "--origin",
        "0",
        "0",
        "0",
        "--fence",
        str(tmp_path / "missing.geojson"),
    )
    assert code == 2 and "does not exist" in err
    assert _site_count(initialised) == 0


def test_duplicate_site_is_refused(initialised, capsys) -> None:
    args = ["site", "create", "demo", "--crs", "EPSG:32618", "--origin", "1", "2", "3"]
    assert run(capsys, *args)[0] == 0
    code, _, err = run(capsys, *args)
    assert code == 2 and "already exists" in err
    assert _site_count(initialised) == 1


def test_commands_refuse_uninitialised_catalog(home, capsys) -> None:
    code, _, err = run(capsys, "site", "list")
    assert code == 2 and "siteline init" in err


def test_db_current_and_downgrade_upgrade(initialised, capsys) -> None:
    code, out, _ = run(capsys, "db", "current", "--json")
    rec = json.loads(out)
    assert rec["up_to_date"] and rec["current"] == rec["head"]
    assert run(capsys, "db", "downgrade", "base")[0] == 0
    code, _, err = run(capsys, "site", "list")
    assert code == 2 and "siteline init" in err
    assert run(capsys, "db", "upgrade")[0] == 0
    code, out, _ = run(capsys, "site", "list", "--json")
    assert code == 0 and json.loads(out) == []


def test_database_url_override(home, capsys, postgres_url, monkeypatch) -> None:
    monkeypatch.setenv("SITELINE_DATABASE_URL", postgres_url)
    assert run(capsys, "init")[0] == 0
    assert run(capsys, "site", "create", "pg", "--crs", "EPSG:32618", "--origin", "1", "2", "3")[0] == 0
    code, out, _ = run(capsys, "site", "list", "--json")
    assert [s["name"] for s in json.loads(out)] == ["pg"]
    assert not (home / "catalog.sqlite").exists()


@pytest.mark.slow  # 27 s: the whole demo twice (`make demo` runs it too); `make test-all` runs it
@pytest.mark.e2e
def test_demo_runs_and_is_rerunnable(home, capsys) -> None:
    # two epochs (one pair) and two training steps: every stage of `make demo`, at half its cost
    code, out, err = run(capsys, "demo", "--epochs", "2", "--train-iters", "2")
    assert code == 0, err
    assert "demo" in out and "10800" in out and "mIoU" in out
    code, out, err = run(capsys, "demo", "--epochs", "2", "--train-iters", "2")
    assert code == 0 and "reusing" in out


@pytest.mark.parametrize(
    ("coordinates", "message"),
    [
        ([[]], "has no vertices"),  # an empty ring
        ([], "one ring without holes"),  # no ring at all
        (5, "must be a list of rings"),  # coordinates that are a number
        ([[5, 6, 7, 5]], "not a number pair"),  # a ring of numbers, not pairs
        ([[["a", "b"], [1, 0], [1, 1], ["a", "b"]]], "not a number pair"),
    ],
)
def test_malformed_fence_is_one_line_not_a_traceback(
    initialised, capsys, tmp_path, coordinates, message
) -> None:
    fence = tmp_path / "fence.geojson"
    fence.write_text(json.dumps({"type": "Polygon", "coordinates": coordinates}))
    code, _, err = run(
        capsys, "site", "create", "x", "--crs", "EPSG:32618", "--origin", "0", "0", "0", "--fence", str(fence)
    )
    assert code == 2 and message in err and "fence.geojson" in err and "Traceback" not in err
    assert _site_count(initialised) == 0
