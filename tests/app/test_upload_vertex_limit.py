"""Issue 28 item 2, work bounded by the input: an upload whose contour has more than CCSM_MAX_CONTOUR_VERTICES
vertices is refused by its check with 413 naming the feature, its count and the limit, before anything is kept;
a MultiLineString's parts count one by one (each is built as a contour of its own)."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from tests.app.conftest import LAT0, LON0, make_settings

GEOJSON = {"content-type": "application/geo+json"}
LIMIT = 500


def wavy(n: int, row: int = 0) -> list[list[float]]:
    """An open line of ``n`` distinct vertices about 9 m apart, south of the synthetic hills."""
    x = LON0 - 0.05 + 0.0001 * np.arange(n)
    y = LAT0 - 0.06 - 0.002 * row + 0.0003 * np.sin(np.arange(n) / 7.0)
    return np.round(np.column_stack([x, y]), 7).tolist()


def line(fid: str, n: int) -> dict:
    return {
        "type": "Feature",
        "properties": {"id": fid, "elevation": 360},
        "geometry": {"type": "LineString", "coordinates": wavy(n)},
    }


def multi(fid: str, *sizes: int) -> dict:
    parts = [wavy(n, row=k) for k, n in enumerate(sizes)]
    return {
        "type": "Feature",
        "properties": {"id": fid, "elevation": 360},
        "geometry": {"type": "MultiLineString", "coordinates": parts},
    }


def fc(*feats: dict) -> str:
    return json.dumps({"type": "FeatureCollection", "features": list(feats)})


@pytest.fixture()
def client(tmp_path: Path, store: Path, synthetic_path: Path) -> Iterator[TestClient]:
    """The real app (lifespan, upload check processes) with a contour limit of LIMIT vertices."""
    settings = make_settings(store, [synthetic_path], max_upload_mb=0.5, build_workers=1, max_contour_vertices=LIMIT)
    with TestClient(create_app(settings), base_url="http://localhost", client=("127.0.0.1", 50000)) as c:
        yield c


def datasets(client: TestClient) -> list[dict]:
    r = client.get("/datasets")
    assert r.status_code == 200, r.text
    return r.json()["datasets"] if isinstance(r.json(), dict) else r.json()


def uploads_left(client: TestClient) -> list[str]:
    return sorted(p.name for p in client.app.state.service.upload_dir.glob("*"))  # type: ignore[attr-defined]


def assert_refused(client: TestClient, body: str, ident: str, named: str, vertices: int) -> None:
    before, files_before = datasets(client), uploads_left(client)
    r = client.post(f"/datasets?id={ident}", content=body, headers=GEOJSON)
    assert r.status_code == 413, r.text
    answer = r.json()
    assert answer["error"] == "contour_too_long", answer
    detail = answer["detail"]
    for word in (repr(named), f"{vertices} vertices", f"the {LIMIT} ", "CCSM_MAX_CONTOUR_VERTICES"):
        assert word in detail, detail
    assert client.get(f"/datasets/{ident}").status_code == 404
    assert datasets(client) == before  # no dataset reserved, the others as they were
    assert uploads_left(client) == files_before  # the streamed file removed, nothing kept


def test_issue_28_a_linestring_over_the_limit_is_413_naming_it(client):
    assert_refused(client, fc(line("long", LIMIT + 1)), "toolong", "long", LIMIT + 1)
    assert client.get("/datasets/hills").json()["state"] == "ready"


def test_issue_28_the_first_over_the_limit_is_named_and_the_others_counted(client):
    body = fc(line("ok", 10), line("long", 2 * LIMIT), line("longer", 3 * LIMIT))
    assert_refused(client, body, "two", "long", 2 * LIMIT)
    assert (
        "1 more contours exceed it" in client.post("/datasets?id=two", content=body, headers=GEOJSON).json()["detail"]
    )


def test_issue_28_a_multilinestring_part_over_the_limit_is_413_naming_the_part(client):
    assert_refused(client, fc(multi("m", 20, LIMIT + 1)), "multi", "m:1", LIMIT + 1)


def test_issue_28_multilinestring_parts_count_one_by_one(client):
    """Two parts of 300 (600 together): each is built as a contour of its own, so neither is over the limit."""
    r = client.post("/datasets?id=parts", content=fc(multi("m", 300, 300)), headers=GEOJSON)
    assert r.status_code == 202, r.text
    client.app.state.service.wait_for_builds(120)  # type: ignore[attr-defined]
    d = client.get("/datasets/parts").json()
    assert d["state"] == "ready" and d["counts"]["contours"] == 2, d


def test_issue_28_a_contour_at_the_limit_is_accepted(client):
    r = client.post("/datasets?id=atlimit", content=fc(line("edge", LIMIT)), headers=GEOJSON)
    assert r.status_code == 202, r.text
    client.app.state.service.wait_for_builds(120)  # type: ignore[attr-defined]
    d = client.get("/datasets/atlimit").json()
    assert d["state"] == "ready" and d["counts"]["contours"] == 1, d
