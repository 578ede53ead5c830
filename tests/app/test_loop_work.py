"""Issue 10, "/healthz within 50 ms under any load": the server process never compresses what the render workers
draw (gzip of a 150 KB tile took 30-80 ms of the event loop on a loaded machine; a /simplify body far more).

Structural: the server process's gzip is made to fail, so any body it compressed itself would be a 500; the
render workers (other processes, untouched) compress instead, and the bodies still decode.
"""

from __future__ import annotations

import pytest

import app.http.responses
from tests.app.conftest import LAT0, LON0
from tests.app.helpers import check_tile, tile_for


@pytest.fixture()
def loop_cannot_gzip(client, monkeypatch):
    def refuse(body: bytes) -> bytes:
        raise AssertionError("the server process compressed a rendered body")

    monkeypatch.setattr(app.http.responses, "gzip_body", refuse)
    return client


@pytest.mark.parametrize(
    "path",
    [
        "/tiles/hills/{z}/{x}/{y}.mvt",
        "/tiles/hills/{z}/{x}/{y}.mvt?method=dp&zoom=12.5",
        "/morph/hills/{z}/{x}/{y}.mvt",
        "/simplify?dataset=hills&scale=100000",
    ],
)
def test_issue_10_rendered_bodies_are_gzipped_by_the_workers(loop_cannot_gzip, path):
    z, x, y = tile_for(LON0, LAT0, 12)
    r = loop_cannot_gzip.get(path.format(z=z, x=x, y=y), headers={"accept-encoding": "gzip"})
    assert r.status_code == 200, r.text
    assert r.headers["content-encoding"] == "gzip" and r.headers["vary"].startswith("Accept-Encoding")
    raw = r.content  # decoded by the client
    assert len(raw) > 512
    if path.startswith("/simplify"):
        assert r.json()["type"] == "FeatureCollection"
    elif path.startswith("/tiles"):
        assert check_tile(raw)


def test_issue_10_identity_clients_get_plain_bodies(loop_cannot_gzip):
    z, x, y = tile_for(LON0, LAT0, 12)
    r = loop_cannot_gzip.get(f"/tiles/hills/{z}/{x}/{y}.mvt", headers={"accept-encoding": "identity"})
    assert r.status_code == 200 and "content-encoding" not in r.headers
    assert check_tile(r.content)
    zipped = loop_cannot_gzip.get(f"/tiles/hills/{z}/{x}/{y}.mvt", headers={"accept-encoding": "gzip"})
    assert zipped.content == r.content
