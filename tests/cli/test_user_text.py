"""Text from users and files is printed as text: a path or a note holding rich markup or terminal
escape sequences neither crashes a command nor styles the terminal; names are checked whole (a
trailing newline or a path is not a name) before anything is written."""

from __future__ import annotations

import laspy
import numpy as np
import pytest
from sitehelpers import run_cli

from siteline.catalog.context import StageContext


def test_a_path_with_markup_is_printed_not_parsed(capsys, home) -> None:
    assert run_cli(capsys, "init")[0] == 0
    code, _, err = run_cli(capsys, "ingest", "missing[/x]", "--site", "nosuch")
    assert code == 2 and "unknown site 'nosuch'" in err and "Traceback" not in err
    code, _, err = run_cli(capsys, "photo", "inspect", "no[/bold]photo.jpg")
    assert code == 2 and "no[/bold]photo.jpg" in err


def test_a_note_with_markup_and_escapes_stays_readable(capsys, scenes, tmp_path, monkeypatch) -> None:
    from siteline.labelsets.export import export_label_set
    from siteline.labelsets.stage import ImportOptions, import_labels

    settings, cat = scenes
    export_label_set(cat, 2, tmp_path / "s2.las")
    las = laspy.read(tmp_path / "s2.las")
    codes = np.asarray(las.classification).copy()
    codes[np.flatnonzero(codes != 255)[:7]] = 6
    las.classification = codes
    las.write(tmp_path / "s2_note.las")
    note = "[/bold] formwork \x1b[31mred\x1b[0m"
    res = import_labels(StageContext(cat, settings), 2, tmp_path / "s2_note.las", ImportOptions(note=note))
    monkeypatch.setenv("SITELINE_HOME", str(settings.home))
    monkeypatch.setenv("SITELINE_DATABASE_URL", settings.database_url)
    for argv in (["labels", "list", "2"], ["labels", "show", "2", str(res.version)]):
        code, out, err = run_cli(capsys, *argv)
        assert code == 0, err
        assert "[/bold]" in out and "\x1b" not in out and "\\x1b[31mred" in out.replace("\n", "")


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--name", "../../x"], "release name '../../x'"),
        (["--name", "R/1.0.0"], "release name 'R/1.0.0'"),
        (["--name", "R\n"], "release name 'R\\n'"),
        (["--name", "R", "--version", "01.0.0"], "version '01.0.0' is not semantic"),
        (["--name", "R", "--version", "1.00.0"], "version '1.00.0' is not semantic"),
        (["--name", "R", "--version", "1.0.0\n"], "version '1.0.0\\n' is not semantic"),
    ],
)
def test_bad_release_names_and_versions_are_refused_before_anything(
    capsys, scenes, monkeypatch, argv, match
) -> None:
    settings, _ = scenes
    monkeypatch.setenv("SITELINE_HOME", str(settings.home))
    monkeypatch.setenv("SITELINE_DATABASE_URL", settings.database_url)
    before = sorted(p for p in settings.home.rglob("*") if ".locks" not in p.parts[-2])
    code, _, err = run_cli(capsys, "release", "build", "--site", "demo", *argv)
    assert code == 2 and match in err.replace("\n", ""), err
    assert sorted(p for p in settings.home.rglob("*") if ".locks" not in p.parts[-2]) == before


def test_a_site_name_with_a_trailing_newline_is_refused(capsys, home) -> None:
    from sitehelpers import SYNTH

    assert run_cli(capsys, "init")[0] == 0
    code, _, err = run_cli(
        capsys, "site", "create", "demo\n", "--crs", SYNTH.crs, "--origin", *map(str, SYNTH.origin)
    )
    assert code == 2 and "site name 'demo\\n' is not allowed" in err
