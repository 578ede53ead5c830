"""``ccsm simplify`` and ``ccsm evaluate`` end to end: on a 60-contour subset of the sample, and one
``simplify`` run on the whole sample."""

from __future__ import annotations

import csv
import json
import math
import re
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest
import shapely
from typer.testing import CliRunner

from app.cli import _register_commands, app
from engine.geom.polyline import closed_path
from engine.io.crs import make_transformer
from engine.io.source import read_source, sample_contours_path, write_geojson
from engine.types import ContourSet

_register_commands()
runner = CliRunner()

SUBSET = 60


@pytest.fixture(scope="module")
def sample_set() -> ContourSet:
    return read_source(sample_contours_path())


@pytest.fixture(scope="module")
def subset_path(tmp_path_factory: pytest.TempPathFactory, sample_set: ContourSet) -> Path:
    """The sample's first 60 contours as a GeoJSON file (EPSG:4326)."""
    path = tmp_path_factory.mktemp("subset") / "subset.geojson"
    write_geojson(
        path,
        ((c.coords, c.closed, {"id": c.id, "elevation": c.elevation}) for c in sample_set.contours[:SUBSET]),
        from_crs=sample_set.working_crs,
    )
    return path


def run(*args: str):  # type: ignore[no-untyped-def]
    return runner.invoke(app, [str(a) for a in args])


def read_csv(path: Path) -> list[dict[str, str]]:
    with path.open() as f:
        return list(csv.DictReader(line for line in f if not line.startswith("#")))


def summary_counts(stdout: str) -> dict[str, int]:
    m = re.search(
        r": (\d+) contours at .*?; (\d+) too small .*?; (\d+) dropped .*?; (\d+) bad feature\(s\); "
        r"(\d+) input feature\(s\)",
        stdout.replace("\n", " "),
    )
    assert m, stdout
    return dict(zip(("written", "vanished", "dropped", "bad", "input"), map(int, m.groups()), strict=True))


# --- simplify ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["ccsm", "dp", "wm", "vw"])
def test_simplify_subset_writes_every_contour_with_properties(
    subset_path: Path, tmp_path: Path, method: str
) -> None:
    out = tmp_path / f"{method}.geojson"
    result = run(
        "simplify", subset_path, "--scale", "250000", "--method", method, "-o", out, "--workers", "1"
    )
    assert result.exit_code == 0, result.output
    counts = summary_counts(result.stdout)
    assert counts["written"] + counts["vanished"] + counts["dropped"] + counts["bad"] == counts["input"] == SUBSET
    features = json.loads(out.read_text())["features"]
    assert len(features) == counts["written"]
    for f in features:
        props = f["properties"]
        assert set(props) >= {"id", "elevation", "t", "similarity", "scale"}
        assert props["scale"] == 250000
        assert 0.0 < props["similarity"] <= 1.0 + 1e-9
        # As in GET /simplify: every method reports the contour's CCSM t at that scale, and its own name.
        assert 0.0 <= props["t"] <= 1.0
        assert props["method"] == method


def test_simplify_output_crs_3857_and_source(subset_path: Path, tmp_path: Path) -> None:
    for crs, name in (("3857", "EPSG:3857"), ("source", None)):
        out = tmp_path / f"{crs}.geojson"
        result = run("simplify", subset_path, "--method", "dp", "--crs", crs, "-o", out)
        assert result.exit_code == 0, result.output
        doc = json.loads(out.read_text())
        if name:
            assert name.split(":")[1] in json.dumps(doc.get("crs"))
        else:
            x, y = doc["features"][0]["geometry"]["coordinates"][0]
            assert -180 <= x <= 180 and -90 <= y <= 90


@pytest.mark.slow
def test_simplify_whole_sample_at_source_scale_returns_the_input(
    sample_set: ContourSet, tmp_path: Path
) -> None:
    out = tmp_path / "all.geojson"
    result = run("simplify", sample_contours_path(), "--scale", "50000", "-o", out, "--crs", "3857")
    assert result.exit_code == 0, result.output
    counts = summary_counts(result.stdout)
    assert counts["written"] + counts["vanished"] + counts["dropped"] + counts["bad"] == counts["input"]
    assert counts["input"] == len(sample_set.contours) + len(sample_set.bad_features)
    features = json.loads(out.read_text())["features"]
    assert len(features) == counts["written"] > 0.9 * counts["input"]
    by_id = {c.id: c for c in sample_set.contours}
    to_working = make_transformer("EPSG:3857", sample_set.working_crs)
    worst = 0.0
    for f in features:
        props = f["properties"]
        assert props["t"] == 0.0
        assert props["similarity"] == pytest.approx(1.0, abs=1e-3)
        c = by_id[props["id"]]
        got = shapely.linestrings(to_working(f["geometry"]["coordinates"]))
        want = shapely.linestrings(closed_path(c.coords) if c.closed else c.coords)
        worst = max(worst, shapely.hausdorff_distance(got, want))
    assert worst < 0.01  # metres


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["simplify", "no/such/file.geojson"], "not found"),
        (["simplify", "{subset}", "--scale", "0"], "--scale"),
        (["simplify", "{subset}", "--scale", "-5"], "--scale"),
        (["simplify", "{subset}", "--scale", "nan"], "--scale"),
        (["simplify", "{subset}", "--method", "bezier"], "unknown method"),
        (["simplify", "{subset}", "--crs", "EPSG:999999"], "CRS"),
        (["simplify", "{subset}", "--target-scale", "10000"], "target_scale"),
        (["evaluate", "no/such/file.geojson", "--out", "x"], "not found"),
        (["evaluate", "{subset}", "--levels", "1"], "--levels"),
        (["evaluate", "{subset}", "--target", "tiny"], "--target"),
        (["evaluate", "{subset}", "--source-scale", "0"], "--source-scale"),
    ],
)
def test_bad_input_exits_2_with_a_message(
    subset_path: Path, tmp_path: Path, args: list[str], message: str
) -> None:
    argv = [a.replace("{subset}", str(subset_path)) for a in args]
    if argv[0] == "simplify":
        argv += ["-o", str(tmp_path / "o.geojson")]
    result = run(*argv)
    assert result.exit_code == 2, result.output
    assert message in result.stderr
    assert "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit)


def test_unreadable_file_exits_2(tmp_path: Path) -> None:
    bad = tmp_path / "broken.geojson"
    bad.write_text("{ not json")
    result = run("simplify", bad, "-o", tmp_path / "o.geojson")
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output


# --- evaluate ---------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def evaluation_dir(subset_path: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("eval")
    result = run(
        "evaluate", subset_path, "--out", out, "--levels", "100", "--table-contours", "5", "--seed", "3"
    )
    assert result.exit_code == 0, result.output
    return out


def test_evaluate_writes_every_file_and_valid_pngs(evaluation_dir: Path) -> None:
    from engine.evaluation.report import FILES

    for name in FILES:
        assert (evaluation_dir / name).is_file(), name
        if name.endswith(".png"):
            image = matplotlib.image.imread(evaluation_dir / name)
            assert image.ndim == 3 and image.shape[0] > 100 and image.shape[1] > 100
    summary = (evaluation_dir / "summary.md").read_text()
    assert "Fig. 10" in summary and "MAAV" in summary


def test_evaluate_csv_columns(evaluation_dir: Path) -> None:
    fig10 = read_csv(evaluation_dir / "fig10_similarity.csv")
    assert len(fig10) == 100
    assert list(fig10[0]) == [
        "level",
        *[f"{m}_mean" for m in ("ccsm", "dp", "wm", "vw")],
        *[f"{m}_std" for m in ("ccsm", "dp", "wm", "vw")],
    ]
    jumps = read_csv(evaluation_dir / "jumps.csv")
    assert [r["method"] for r in jumps] == ["ccsm", "dp", "wm", "vw"]
    crossings = read_csv(evaluation_dir / "crossings.csv")
    assert set(crossings[0]) == {"method", "level", "pairs_intersecting", "pairs_crossing"}
    assert len(crossings) == 4 * 100
    assert all(int(r["pairs_intersecting"]) == 0 for r in crossings if r["level"] == "1")
    table2 = read_csv(evaluation_dir / "table2_maav.csv")
    assert 1 <= len(table2) <= 5
    assert {"maav", "maav_with_vw", "sd_dp_ccsm", "sd_dp_wm", "sd_wm_ccsm", "groups"} <= set(table2[0])
    assert all(float(r["maav"]) < 0.002 for r in table2)
    density = read_csv(evaluation_dir / "fig11_linear_density.csv")
    assert set(density[0]) == {"contour", "id", "ccsm", "dp", "wm", "vw"}
    table3 = read_csv(evaluation_dir / "table3_positional_error.csv")
    assert [r["method"] for r in table3] == ["ccsm", "dp", "wm", "vw"]
    for r in table3:
        assert 0 <= float(r["mean_m"]) <= float(r["max_m"])


def test_evaluate_ccsm_curve_is_continuous(evaluation_dir: Path) -> None:
    fig10 = read_csv(evaluation_dir / "fig10_similarity.csv")
    ccsm = np.array([float(r["ccsm_mean"]) for r in fig10])
    dp = np.array([float(r["dp_mean"]) for r in fig10])
    assert ccsm[0] == pytest.approx(1.0, abs=1e-3)
    assert np.all(np.diff(ccsm) <= 1e-9), np.diff(ccsm).max()
    jumps = {r["method"]: r for r in read_csv(evaluation_dir / "jumps.csv")}
    assert float(jumps["ccsm"]["mean_curve_jump"]) < float(jumps["dp"]["mean_curve_jump"])
    assert float(jumps["ccsm"]["contour_jump_mean"]) < float(jumps["dp"]["contour_jump_mean"])
    assert float(jumps["ccsm"]["mean_curve_rise_max"]) <= 1e-9
    assert int(jumps["ccsm"]["contours_rising"]) <= int(jumps["dp"]["contours_rising"])
    assert math.isfinite(dp[-1])


def _older_format_store(path: Path) -> None:
    """A store file as an earlier ccsm, with another store format, left it."""
    import sqlite3

    from engine.store.store import CCSStore

    CCSStore(path).close()
    con = sqlite3.connect(path)
    with con:
        con.execute("UPDATE store_meta SET value = '2' WHERE key = 'format'")
    con.close()


def _meta(path: Path) -> list[tuple[str, str]]:
    import sqlite3

    con = sqlite3.connect(path)
    try:
        return sorted(con.execute("SELECT key, value FROM store_meta"))
    finally:
        con.close()


def test_simplify_replaces_a_default_cache_of_an_older_store_format(subset_path, tmp_path, monkeypatch) -> None:
    from engine.store.schema import STORE_FORMAT
    from engine.store.store import CCSStore

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    cache = tmp_path / "cache" / "ccsm" / "sources.ccsm.sqlite"
    cache.parent.mkdir(parents=True)
    _older_format_store(cache)
    result = run("simplify", subset_path, "--method", "dp", "-o", tmp_path / "out.geojson", "--workers", "1")
    assert result.exit_code == 0, result.output
    assert CCSStore(cache, readonly=True).dataset_ids()  # a new cache of this format, holding the source
    assert STORE_FORMAT != 2


def test_simplify_never_replaces_a_store_given_with_store(subset_path, tmp_path) -> None:
    mine = tmp_path / "mine.sqlite"
    _older_format_store(mine)
    before = _meta(mine)
    result = run("simplify", subset_path, "--store", mine, "-o", tmp_path / "out.geojson", "--workers", "1")
    assert result.exit_code == 2
    assert "has format 2" in result.output
    assert _meta(mine) == before and ("format", "2") in before  # the user's store kept as it was
