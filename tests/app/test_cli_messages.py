"""Issue 27 item 4, messages a user can act on: each bad input told in the CLI's own words (the file, the
option to give), no progress bar before the input is read, repeated per-feature warnings summarised (every one
in ``--report FILE``), ``ccsm --help`` whole, and ``make install`` saying what its one-time steps cost."""

from __future__ import annotations

import csv
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from app.cli import _register_commands, app
from engine.io.source import sample_dem_path
from tests.app.conftest import REPO

_register_commands()


def ccsm(*args: object, columns: int = 80) -> subprocess.CompletedProcess[str]:
    """The real ``ccsm`` command in a process of its own, on a terminal ``columns`` wide."""
    return subprocess.run(
        [sys.executable, "-c", "from app.cli import main; main()", *map(str, args)],
        env={**os.environ, "COLUMNS": str(columns)},
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=600,
    )


def one_line(text: str) -> str:
    return " ".join(text.split())


def assert_bad_input(done: subprocess.CompletedProcess[str], *words: str) -> str:
    """Exit 2, no traceback, no progress bar drawn, and each of ``words`` in the message; returns it."""
    assert done.returncode == 2, done.stdout + done.stderr
    both = done.stdout + done.stderr
    assert "Traceback" not in both
    assert "0/?" not in both and "━" not in both, both  # the bar (━ and its count) is drawn only once read
    message = one_line(done.stderr)
    for word in words:
        assert word in message, message
    return message


def simplify_refuses(tmp_path: Path, name: str, text: str, *words: str) -> str:
    """``ccsm simplify`` of a file ``name`` holding ``text``: :func:`assert_bad_input` of it with ``words``."""
    source = tmp_path / name
    source.write_text(text)
    return assert_bad_input(
        ccsm("simplify", source, "-o", tmp_path / "o.geojson", "--store", tmp_path / "s.sqlite"), *words
    )


def test_an_empty_feature_collection_says_the_file_has_no_features(tmp_path: Path) -> None:
    message = simplify_refuses(
        tmp_path,
        "empty.geojson",
        '{"type": "FeatureCollection", "features": []}',
        "empty.geojson: the file has no features",
    )
    assert "elevation" not in message


def test_a_file_that_is_not_geojson_is_told_in_ccsm_words(tmp_path: Path) -> None:
    message = simplify_refuses(
        tmp_path,
        "notes.geojson",
        "these are my notes, not contours\n",
        "notes.geojson: the file could not be read as contour lines",
        "GeoJSON",
        "GeoPackage",
        "Shapefile",
        "GeoTIFF",
        "none of them",
    )
    assert "DRIVER" not in message and "driver" not in message, message


@pytest.mark.parametrize("command", ["simplify", "build", "export"])
def test_a_dem_without_interval_names_the_option(tmp_path: Path, command: str) -> None:
    out = {"simplify": ("-o", tmp_path / "o.geojson"), "build": (), "export": ("-o", tmp_path / "a.pmtiles")}
    message = assert_bad_input(
        ccsm(command, sample_dem_path(), *out[command], "--store", tmp_path / "s.sqlite"),
        "jacksboro_fault_dem.npz: a DEM needs a contour interval",
        "give --interval N",
    )
    assert "interval=" not in message


def test_a_contour_file_without_elevation_names_the_option(tmp_path: Path) -> None:
    line = {"type": "LineString", "coordinates": [[-84.25, 36.6], [-84.24, 36.61]]}
    feature = {"type": "Feature", "properties": {"alt": 400}, "geometry": line}
    message = simplify_refuses(
        tmp_path,
        "unnamed.geojson",
        json.dumps({"type": "FeatureCollection", "features": [feature]}),
        "unnamed.geojson: no elevation field found",
        "available fields: alt",
        "give --elevation-field NAME",
    )
    assert "elevation_field" not in message


def test_an_upload_without_elevation_names_the_query_parameter(client) -> None:  # type: ignore[no-untyped-def]
    line = {"type": "LineString", "coordinates": [[-84.25, 36.6], [-84.24, 36.61]]}
    body = json.dumps({"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"alt": 400}, "geometry": line}]})
    r = client.post("/datasets?id=noelev", content=body, headers={"content-type": "application/geo+json"})
    assert r.status_code == 400, r.text
    detail = r.json()["detail"]
    assert "no elevation field found" in detail and "give the query parameter elevation_field" in detail, detail
    assert "--elevation-field" not in detail


def test_report_of_another_format_exits_2_before_any_build(tmp_path: Path) -> None:
    assert_bad_input(
        ccsm("simplify", sample_dem_path(), "--interval", "10", "--report", tmp_path / "r.txt",
             "--store", tmp_path / "s.sqlite"),
        "--report", "r.txt", ".json or .csv",
    )


# --- per-feature warnings, summarised ------------------------------------------------------------------


@pytest.fixture(scope="module")
def integer_dem(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A corner of the sample DEM with heights rounded to 5 m: at a 10 m interval every level passes through
    grid nodes, and tiny rings around them are skipped as degenerate (dozens of them)."""
    grid = dict(np.load(sample_dem_path()))
    n = 60
    grid["elevation"] = np.round(grid["elevation"][:n, :n] / 5) * 5
    grid["xmax"] = grid["xmin"] + grid["dx"] * n
    grid["ymin"] = grid["ymax"] - grid["dy"] * n
    path = tmp_path_factory.mktemp("integer") / "integer.npz"
    np.savez(path, **grid)
    return path


@pytest.fixture()
def labels_fail_from_400_to_600(monkeypatch: pytest.MonkeyPatch) -> None:
    """The labels of every contour from 400 to 600 m fail: the build serves them without labels, as contour
    issues (more than a table's worth)."""
    import engine.cartography.labels as labels

    candidates = labels.contour_candidates

    def failing(src, *args):  # type: ignore[no-untyped-def]
        if 400.0 <= src.elevation <= 600.0:
            raise RuntimeError("no room for a label")
        return candidates(src, *args)

    monkeypatch.setattr(labels, "contour_candidates", failing)


def summary_of(output: str, kind: str) -> list[str]:
    return [line.strip() for line in output.splitlines() if kind in line]


@pytest.mark.slow
@pytest.mark.usefixtures("labels_fail_from_400_to_600")
def test_repeated_warnings_are_summarised_and_all_in_the_report(integer_dem: Path, tmp_path: Path) -> None:
    runner = CliRunner()
    report = tmp_path / "report.json"
    store = tmp_path / "cache.sqlite"
    done = runner.invoke(app, ["simplify", str(integer_dem), "--interval", "10", "-o", str(tmp_path / "o.geojson"),
                               "--store", str(store), "--workers", "1", "--report", str(report)],
                         env={"COLUMNS": "100"})
    assert done.exit_code == 0, done.output
    degenerate = summary_of(done.output, "degenerate")
    assert len(degenerate) == 1, done.output  # one line, not one per ring
    m = re.fullmatch(r"(\d+) features skipped: degenerate contour \(e\.g\. .*\) — ids ((?:[\d.]+:\d+, ){5})…; "
                     rf"all in {re.escape(str(report))}", one_line(degenerate[0]))
    assert m, degenerate[0]
    skipped = int(m.group(1))
    assert skipped > 10
    issues = summary_of(done.output, "served without:")
    assert len(issues) == 1, done.output
    m_issues = re.search(r"(\d\d+) contours served without: labels \(e\.g\. RuntimeError: no room for a label\)",
                         one_line(issues[0]))
    assert m_issues, issues[0]

    doc = json.loads(report.read_text())
    assert len(doc["skipped_features"]) == skipped
    assert all(b["reason"].startswith("degenerate contour") for b in doc["skipped_features"])
    assert m.group(2).rstrip(", ").split(", ") == [b["id"] for b in doc["skipped_features"][:5]]
    assert len(doc["contour_issues"]) == int(m_issues.group(1))
    assert {i["step"] for i in doc["contour_issues"]} == {"labels"}
    assert all(400 <= float(i["id"].split(":")[0]) <= 600 for i in doc["contour_issues"])

    # The same report as CSV, from ccsm build into a store of its own and from ccsm export of the cached build.
    for args, name in (
        (["build", str(integer_dem), "--store", str(tmp_path / "s.sqlite")], "build.csv"),
        (["export", str(integer_dem), "-o", str(tmp_path / "a.pmtiles"), "--store", str(store),
          "--minzoom", "8", "--maxzoom", "9"], "export.csv"),
    ):
        done = runner.invoke(app, [*args, "--interval", "10", "--workers", "1", "--report", str(tmp_path / name)])
        assert done.exit_code == 0, done.output
        assert len(summary_of(done.output, "degenerate")) == 1, done.output
        with (tmp_path / name).open(newline="") as fh:
            rows = list(csv.DictReader(fh))
        assert [r["id"] for r in rows if r["kind"] == "skipped_feature"] == [
            b["id"] for b in doc["skipped_features"]]
        assert sorted(r["id"] for r in rows if r["kind"] == "contour_issue") == sorted(
            i["id"] for i in doc["contour_issues"])


# --- help and make --------------------------------------------------------------------------------------


def test_help_lists_every_command_with_its_whole_summary() -> None:
    import typer

    done = ccsm("--help", columns=80)
    assert done.returncode == 0, done.stderr
    page = one_line(done.stdout)
    group = typer.main.get_command(app)
    names = sorted(group.commands)  # type: ignore[attr-defined]
    assert {"simplify", "evaluate", "export", "serve", "build"} <= set(names)
    for name in names:
        doc = group.commands[name].callback.__doc__  # type: ignore[attr-defined]
        summary = one_line(doc.strip().split("\n\n")[0])
        assert summary.endswith("."), f"{name}'s summary is not a whole sentence: {summary!r}"
        assert f"{name} {summary}" in page, f"ccsm --help cut {name!r}: {page}"
    assert "..." not in page.split("Commands:", 1)[1]


def test_serve_help_says_what_interval_defaults_to() -> None:
    done = ccsm("serve", "--help", columns=200)
    assert done.returncode == 0, done.stderr
    option = one_line(done.stdout).split("--interval", 1)[1].split(" --", 1)[0]
    assert "[contour files: from their levels; needed for a DEM]" in option, option


def test_make_install_says_what_each_one_time_step_does_before_it() -> None:
    recipe = (REPO / "Makefile").read_text().split(".install-stamp:", 1)[1].split("\ninstall:", 1)[0]
    steps = [line.strip() for line in recipe.splitlines() if line.startswith("\t")]
    pip = next(i for i, s in enumerate(steps) if "pip install" in s)
    warmup = next(i for i, s in enumerate(steps) if "engine.warmup" in s)
    assert re.fullmatch(r'@echo "installing Python packages into \$\(VENV\) \(one time, ~1 min\)"', steps[pip - 1])
    assert re.fullmatch(r'@echo "compiling numba kernels \(one time, ~45 s\)"', steps[warmup - 1])
    assert "npm ci (one time," in recipe
