"""Issue 24, "a failure stays with its contour": a contour whose labels, surface or crossing repair cannot be
made is served without that part and listed, with its id and the reason, in the build's report (the store),
in the CLI's summary and in ``GET /datasets/{id}``; a dataset fails only when no contour can be served, and
then says which step of which contour; the CLI prints no traceback, exit 2 on bad data and 1 (with the path of
a log) on an internal error.

Faults are injected into one contour's step of the real processes (the service's build processes, the real
CLI) by ``tests/fault_hooks/sitecustomize.py``, named by ``CCSM_TEST_FAULT``.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient
from support.server import wait_ready
from typer.testing import CliRunner

from app.cli import _register_commands, app
from app.main import create_app
from engine.store.store import CCSStore
from tests.app.conftest import LAT0, LON0, REPO, make_settings, synthetic_features, write_geojson

pytestmark = pytest.mark.slow

_register_commands()
HOOKS = REPO / "tests" / "fault_hooks"
M_LAT = 1 / 111_320  # degrees of latitude per metre
M_LON = M_LAT / np.cos(np.radians(LAT0))


def _feature(ident: str, elevation: float, xy_m: np.ndarray, east: float, north: float) -> dict:
    lonlat = np.column_stack([LON0 + east + xy_m[:, 0] * M_LON, LAT0 + north + xy_m[:, 1] * M_LAT])
    return {
        "type": "Feature",
        "properties": {"id": ident, "elevation": elevation},
        "geometry": {"type": "LineString", "coordinates": np.round(lonlat, 9).tolist()},
    }


def _ring(radius_m: float, n: int) -> np.ndarray:
    a = np.linspace(0, 2 * np.pi, n)
    xy = np.column_stack([radius_m * np.cos(a), radius_m * np.sin(a)])
    xy[-1] = xy[0]
    return xy


def issue_features() -> list[dict]:
    """The service tests' hills, plus: 'solo', a lone 700 m index ring that gets labels; 'kinked' and 'short',
    two lines the crossing repair rebuilds (the kinked one straightened at the target would cross the short
    one); 'speck', a 0.25 m index ring whose first label zoom lies past the last zoom (the crash of issue 24)."""
    x = np.linspace(0, 2000, 41)
    kinked = np.column_stack([x, -40 * (1 - np.abs(x - 1000) / 1000)])
    short = np.column_stack([np.linspace(800, 1200, 9), np.full(9, -25.0)])
    return synthetic_features() + [
        _feature("kinked", 300, kinked, 0.0, -0.06),
        _feature("short", 320, short, 0.0, -0.06),
        _feature("solo", 700, _ring(2000, 200), 0.09, 0.0),
        _feature("speck", 800, _ring(0.25, 9), 0.09, 0.0),
    ]


@pytest.fixture(scope="module")
def issue_source(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_geojson(tmp_path_factory.mktemp("issues") / "issues.geojson", issue_features())


def fault_env(fault: str) -> dict[str, str]:
    """The environment of a process with ``fault`` injected (the worktree's code first on the path)."""
    path = os.pathsep.join([str(HOOKS), str(REPO), os.environ.get("PYTHONPATH", "")])
    return {**os.environ, "PYTHONPATH": path, "CCSM_TEST_FAULT": fault}


@contextmanager
def service(store: Path, source: Path, fault: str, monkeypatch: pytest.MonkeyPatch) -> Iterator[TestClient]:
    """The app (lifespan on) serving ``source``, built at startup in its own process with ``fault`` injected."""
    for key, value in fault_env(fault).items():
        monkeypatch.setenv(key, value)
    with TestClient(create_app(make_settings(store, [source], build_workers=1)), base_url="http://localhost") as c:
        yield c


def fid_of(store: CCSStore, dataset: str, contour_id: str) -> int:
    (fid,) = [r.fid for r in store.load(store.all_fids(dataset)) if r.contour_id == contour_id]
    return fid


@pytest.mark.parametrize(
    ("fault", "contour", "step"),
    [("labels:700", "solo", "labels"), ("surface:solo", "solo", "surface"), ("repair:kinked", "kinked", "repair")],
)
def test_one_contour_failing_a_step_is_served_without_it_and_listed(
    tmp_path: Path, issue_source: Path, monkeypatch: pytest.MonkeyPatch, fault: str, contour: str, step: str
) -> None:
    store_path = tmp_path / "ccsm.sqlite"
    with service(store_path, issue_source, fault, monkeypatch) as client:
        d = wait_ready(client, "issues", timeout=300.0)
        assert d["state"] == "ready", d["build"]
        store = CCSStore(store_path, readonly=True)
        fid = fid_of(store, "issues", contour)
        assert d["counts"]["contours"] == len(issue_features())  # every contour served, 'speck' too
        assert d["counts"]["contour_issues"] == 1, d["contour_issues"]
        (issue,) = d["contour_issues"]
        assert (issue["fid"], issue["id"], issue["step"]) == (fid, contour, step)
        assert issue["reason"] == f"InjectedFault: injected {step} fault"
        labelled = set(store.labels("issues").anchors.fid.tolist())
        (record,) = store.load([fid])
        if step == "labels":
            assert fid not in labelled  # no label, the line itself as built
            assert not np.allclose(record.base, record.top)
        else:  # served as its input line at every scale
            assert np.array_equal(record.base, record.top)
            assert np.allclose(record.base, record.original)
            assert fid in labelled or step == "repair"  # a contour without its surface is still labelled
        # the line is in the tiles of its dataset
        assert any(c["id"] == fid for c in client.get("/simplify", params={"dataset": "issues", "scale": 50_000})
                   .json()["features"])


def test_the_same_build_without_a_fault_labels_solo_and_lists_nothing(
    tmp_path: Path, issue_source: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """What the fault tests compare with: 'solo' is labelled and surfaced, 'kinked' repaired, nothing listed;
    and 'speck' (first labelled past the last zoom) no longer stops the build."""
    store_path = tmp_path / "ccsm.sqlite"
    with service(store_path, issue_source, "", monkeypatch) as client:
        d = wait_ready(client, "issues", timeout=300.0)
    assert d["state"] == "ready", d["build"]
    assert (d["contour_issues"], d["counts"]["contour_issues"]) == ([], 0)
    store = CCSStore(store_path, readonly=True)
    assert fid_of(store, "issues", "solo") in set(store.labels("issues").anchors.fid.tolist())
    (kinked,) = store.load([fid_of(store, "issues", "kinked")])
    assert not np.array_equal(kinked.base, kinked.top)


def test_a_dataset_none_of_whose_contours_can_be_served_fails_naming_step_and_contour(
    tmp_path: Path, issue_source: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    with service(tmp_path / "ccsm.sqlite", issue_source, "surface+input:*", monkeypatch) as client:
        d = wait_ready(client, "issues", timeout=300.0)
    assert d["state"] == "failed"
    error = d["build"]["error"]
    assert re.search(r"nothing to serve: none of the \d+ contour\(s\) could be built; contour 'h0': surface step "
                     r"failed: InjectedFault: injected surface\+input fault", error), error


# --- the CLI ----------------------------------------------------------------------------------------------


def ccsm(*args: object, fault: str = "") -> subprocess.CompletedProcess[str]:
    """The real ``ccsm`` command in a process of its own."""
    return subprocess.run(
        [sys.executable, "-c", "from app.cli import main; main()", *map(str, args)],
        env=fault_env(fault),
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=600,
    )


def table_text(output: str) -> str:
    """The CLI's output with the table's rules dropped and white space collapsed."""
    return " ".join(re.sub(r"[│┃┏┓┗┛┡┩└┘━─┳┻╇┴]", " ", output).split())


def test_cli_summaries_list_the_contour_and_its_reason(
    tmp_path: Path, issue_source: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import engine.cartography.labels as labels

    candidates = labels.contour_candidates

    def failing(src, *args):  # type: ignore[no-untyped-def]
        if src.elevation == 700.0:
            raise RuntimeError("no room\nfor a label")
        return candidates(src, *args)

    monkeypatch.setattr(labels, "contour_candidates", failing)
    runner = CliRunner()
    store = tmp_path / "cache.sqlite"
    out = tmp_path / "out.geojson"
    simplified = runner.invoke(
        app, ["simplify", str(issue_source), "--scale", "40000", "-o", str(out), "--store", str(store),
              "--workers", "1"]
    )
    assert simplified.exit_code == 0, simplified.output
    text = table_text(simplified.output)
    assert "1 contour(s) served without part of their build" in text
    assert re.search(r"\d+ solo labels RuntimeError: no room for a label", text), text
    built = runner.invoke(app, ["build", str(issue_source), "--store", str(tmp_path / "s.sqlite"), "--workers", "1"])
    assert built.exit_code == 0, built.output
    assert "1 contour(s) served without part of their build" in table_text(built.output)
    exported = runner.invoke(
        app, ["export", str(issue_source), "-o", str(tmp_path / "a.pmtiles"), "--store", str(store),
              "--maxzoom", "10", "--workers", "1"]
    )
    assert exported.exit_code == 0, exported.output
    assert re.search(r"\d+ solo labels RuntimeError: no room for a label", table_text(exported.output))


def test_cli_exits_2_with_a_message_when_no_contour_can_be_built(tmp_path: Path, issue_source: Path) -> None:
    done = ccsm("simplify", issue_source, "-o", tmp_path / "o.geojson", "--store", tmp_path / "s.sqlite",
                "--workers", "1", fault="surface+input:*")
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr + done.stdout
    assert "nothing to serve" in done.stderr and "contour 'h0': surface step failed" in done.stderr


def test_cli_exits_1_pointing_to_a_log_on_an_internal_error(tmp_path: Path, issue_source: Path) -> None:
    done = ccsm("simplify", issue_source, "-o", tmp_path / "o.geojson", "--store", tmp_path / "s.sqlite",
                "--workers", "1", fault="internal:simplify")
    assert done.returncode == 1, done.stderr
    assert "Traceback" not in done.stderr + done.stdout
    m = re.search(r"internal error: InjectedFault: injected internal error; the traceback is in (\S+\.log)",
                  done.stderr)
    assert m, done.stderr
    log = Path(m.group(1))
    assert "Traceback" in log.read_text() and "InjectedFault" in log.read_text()
    log.unlink()
