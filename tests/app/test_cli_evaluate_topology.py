"""``ccsm evaluate`` counts, per scale and method, the pairs of contours apart in the input that touch or cross
(issue 13), on a hand-made input whose answer is known."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from app.cli import _register_commands, app
from engine.io.source import write_geojson

_register_commands()
runner = CliRunner()

ORIGIN = np.array([500_000.0, 5_000_000.0])  # UTM 32N, metres


@pytest.fixture(scope="module")
def tent(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tent-shaped contour 40 m high over 1 km, and a short line standing under its peak, 10 m below it.

    Douglas-Peucker at 0.1 mm x S (epsilon 40 m at 1:400,000) flattens the tent onto its base, straight
    through the short line: below 1:400,000 they are apart, above it they cross.
    """
    path = tmp_path_factory.mktemp("tent") / "tent.geojson"
    lines = [
        (np.array([[0.0, 0.0], [500.0, 40.0], [1000.0, 0.0]]), 100.0),
        (np.array([[500.0, -10.0], [500.0, 30.0]]), 120.0),
    ]
    write_geojson(
        path,
        ((xy + ORIGIN, False, {"id": k, "elevation": ele}) for k, (xy, ele) in enumerate(lines)),
        from_crs="EPSG:32632",
    )
    return path


def topology_rows(out: Path) -> list[dict[str, str]]:
    with (out / "topology_by_scale.csv").open() as f:
        return list(csv.DictReader(line for line in f if not line.startswith("#")))


def test_evaluate_counts_the_pairs_douglas_peucker_makes_cross(tent: Path, tmp_path: Path) -> None:
    # Scales 1:100,000 and 1:1,000,000 (from the source scale to twice the target scale).
    result = runner.invoke(
        app,
        [
            "evaluate", str(tent), "--out", str(tmp_path), "--levels", "10", "--table-contours", "0",
            "--source-scale", "100000", "--target-scale", "500000", "--topology-scales", "2", "--workers", "1",
        ],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    rows = topology_rows(tmp_path)
    assert [int(r["scale"]) for r in rows] == [100_000, 1_000_000]
    assert [int(r["dp"]) for r in rows] == [0, 1]
    assert [int(r["ccsm"]) for r in rows] == [0, 0]  # as served: the build's repair keeps them apart
    text = " ".join(result.output.split())  # the console table's title wraps on a narrow terminal
    assert "1:1,000,000" in text and "touch or cross" in text


def test_evaluate_without_the_topology_table(tent: Path, tmp_path: Path) -> None:
    result = runner.invoke(
        app,
        ["evaluate", str(tent), "--out", str(tmp_path), "--levels", "10", "--table-contours", "0",
         "--topology-scales", "0", "--workers", "1"],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert not (tmp_path / "topology_by_scale.csv").exists()


def test_a_negative_number_of_topology_scales_is_refused(tent: Path, tmp_path: Path) -> None:
    result = runner.invoke(app, ["evaluate", str(tent), "--out", str(tmp_path), "--topology-scales", "-1"])
    assert result.exit_code == 2
    assert "--topology-scales" in result.output
