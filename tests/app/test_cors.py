"""Issue 28 item 4: a refused CORS preflight answers in the service's JSON error form, like every other error."""

from __future__ import annotations

from tests.app.conftest import LAT0, LON0
from tests.app.helpers import tile_for

PATH = "/tiles/hills/{}/{}/{}.mvt".format(*tile_for(LON0, LAT0, 12))


def test_refused_preflight_is_a_json_error_naming_what_was_refused(client) -> None:
    # Writes are never granted cross-site: a preflight for POST is refused.
    r = client.options(PATH, headers={"origin": "https://x.org", "access-control-request-method": "POST"})
    assert r.status_code == 400
    assert r.headers["content-type"].startswith("application/json")
    body = r.json()
    assert body["error"] == "cors_preflight_refused"
    assert "method" in body["detail"]
    assert body["request_id"] == r.headers["x-request-id"]


def test_granted_preflight_is_unchanged(client) -> None:
    r = client.options(PATH, headers={"origin": "https://x.org", "access-control-request-method": "GET"})
    assert r.status_code == 200
    assert r.headers["access-control-allow-origin"] == "*"
    assert "GET" in r.headers["access-control-allow-methods"]
