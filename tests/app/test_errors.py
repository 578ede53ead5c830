"""Bad requests get a 4xx with a JSON body that says what is wrong, and hurt nothing."""

import json

import pytest
from support.server import wait_ready

from tests.app.conftest import LAT0, LON0, synthetic_features
from tests.app.helpers import check_tile, tile_for

BAD_GETS = [
    ("/tiles/hills/17/0/0.mvt", 404, "zoom 17"),
    ("/tiles/hills/31/0/0.mvt", 422, "z"),
    ("/tiles/hills/3/8/0.mvt", 404, "x 8"),
    ("/tiles/hills/3/0/8.mvt", 404, "y 8"),
    ("/tiles/hills/3/-1/0.mvt", 422, "x"),
    ("/tiles/hills/3/a/0.mvt", 422, "x"),
    ("/tiles/hills/12/1088/1598.mvt?zoom=13", 400, "zoom 13"),
    ("/tiles/hills/12/1088/1598.mvt?zoom=11.9", 400, "zoom 11.9"),
    ("/tiles/hills/12/1088/1598.mvt?zoom=nan", 422, "finite"),
    ("/tiles/hills/12/1088/1598.mvt?zoom=inf", 422, "finite"),
    ("/tiles/hills/12/1088/1598.mvt?method=foo", 422, "method"),
    ("/tiles/hills/12/1088/1598.mvt?t=1.5", 422, "t"),
    ("/tiles/nope/12/1088/1598.mvt", 404, "nope"),
    ("/tiles/nope/tilejson.json", 404, "nope"),
    ("/simplify?scale=0", 422, "greater than 0"),
    ("/simplify?scale=-5", 422, "greater than 0"),
    ("/simplify?scale=nan", 422, "finite"),
    ("/simplify?scale=1e400", 422, "finite"),
    ("/simplify?scale=1e12", 422, "less than"),
    ("/simplify", 422, "scale"),
    ("/simplify?scale=1000&method=xx", 422, "method"),
    ("/simplify?scale=1000&dataset=nope", 404, "nope"),
    ("/simplify?scale=1000&bbox=1,2,3", 400, "4 numbers"),
    ("/simplify?scale=1000&bbox=a,b,c,d", 400, "four numbers"),
    ("/simplify?scale=1000&bbox=10,0,5,1", 400, "min > max"),
    ("/simplify?scale=1000&bbox=0,10,1,5", 400, "min > max"),
    ("/simplify?scale=1000&bbox=0,0,200,1", 400, "outside"),
    ("/datasets/nope", 404, "nope"),
    ("/no/such/route", 404, "Not Found"),
]


def assert_clean(body: str) -> None:
    assert "Traceback" not in body and "/tmp" not in body and "/work" not in body and ".py" not in body


@pytest.mark.parametrize(("path", "status", "words"), BAD_GETS)
def test_bad_get(client, path, status, words):
    r = client.get(path)
    assert r.status_code == status, r.text
    body = r.json()
    assert set(body) == {"error", "detail", "request_id"}
    assert words.lower() in json.dumps(body).lower()
    assert_clean(r.text)
    assert client.get("/healthz").status_code == 200


@pytest.mark.parametrize(
    ("body", "status"),
    [
        (b"{not json", 400),
        (b"[1, 2]", 400),
        (json.dumps({"type": "FeatureCollection"}).encode(), 400),
        (json.dumps({"type": "FeatureCollection", "features": []}).encode(), 400),
        (
            json.dumps(
                {
                    "type": "FeatureCollection",
                    "features": [
                        {
                            "type": "Feature",
                            "properties": {"elevation": 1},
                            "geometry": {"type": "Point", "coordinates": [0, 0]},
                        }
                    ],
                }
            ).encode(),
            400,
        ),
        (b"\xff\xfe\x00", 400),
        (b"x" * (600 * 1024), 413),
    ],
)
def test_bad_upload(client, body, status):
    before = client.get("/datasets").json()
    r = client.post("/datasets", content=body, headers={"content-type": "application/geo+json"})
    assert r.status_code == status, r.text
    assert set(r.json()) == {"error", "detail", "request_id"}
    assert_clean(r.text)
    assert client.get("/datasets").json() == before
    tile = client.get("/tiles/hills/{}/{}/{}.mvt".format(*tile_for(LON0, LAT0, 12)))
    assert tile.status_code == 200 and len(check_tile(tile.content)) > 5  # hills is still served


#: A valid upload: only the query parameters can make it fail.
GOOD_UPLOAD = json.dumps({"type": "FeatureCollection", "features": synthetic_features(seed=5)[:3]}).encode()


@pytest.mark.parametrize(
    ("query", "status", "names"),
    [
        ("source_scale=100000&target_scale=50000", 400, "target_scale"),
        ("source_scale=600000", 400, "source_scale"),  # above the default target scale, 1:500,000
        ("source_scale=-5", 422, "source_scale"),
        ("target_scale=nan", 422, "target_scale"),
        ("interval=0", 422, "interval"),
        ("id=Bad%20Id", 422, "id"),
    ],
)
def test_bad_upload_parameters(client, query, status, names):
    before = client.get("/datasets").json()
    r = client.post(f"/datasets?{query}", content=GOOD_UPLOAD, headers={"content-type": "application/geo+json"})
    assert r.status_code == status, r.text
    body = r.json()
    assert set(body) == {"error", "detail", "request_id"}
    assert names in json.dumps(body["detail"]), body
    assert_clean(r.text)
    assert client.get("/datasets").json() == before


def test_good_upload_parameters_are_accepted(client):
    # The control of test_bad_upload_parameters: the same body with valid parameters is accepted.
    r = client.post(
        "/datasets?id=good&source_scale=100000&target_scale=400000",
        content=GOOD_UPLOAD,
        headers={"content-type": "application/geo+json"},
    )
    assert r.status_code == 202, r.text
    scales = wait_ready(client, "good")["scales"]
    assert (scales["source_scale"], scales["target_scale"]) == (100000.0, 400000.0)


def test_internal_error_is_generic(client, monkeypatch):
    def boom(*a, **k):
        raise RuntimeError("secret /etc/passwd detail")

    from fastapi.testclient import TestClient

    monkeypatch.setattr(client.app.state.render_lanes.light, "run", boom)
    r = TestClient(client.app, raise_server_exceptions=False).get("/tiles/hills/12/1088/1598.mvt")
    assert r.status_code == 500
    assert r.json()["error"] == "internal_error" and "secret" not in r.text
    assert r.json()["request_id"] == r.headers["x-request-id"]
    assert client.get("/healthz").status_code == 200


def test_openapi_describes_every_parameter(client):
    spec = client.get("/openapi.json").json()
    for path, ops in spec["paths"].items():
        for op in ops.values():
            for p in op.get("parameters", []):
                assert p.get("description"), (path, p["name"])
