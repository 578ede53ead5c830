import json

from support.server import wait_ready

from tests.app.conftest import synthetic_features
from tests.app.helpers import check_tile, tile_for


def test_list(client):
    items = client.get("/datasets").json()
    assert [(i["id"], i["state"]) for i in items] == [("hills", "ready")]
    assert set(items[0]) >= {"id", "name", "state"}


def test_detail(client):
    d = client.get("/datasets/hills").json()
    assert d["state"] == "ready"
    assert d["counts"]["contours"] == 28
    assert len(d["bounds"]) == 4 and d["bounds"][0] < d["bounds"][2]
    assert d["scales"]["source_scale"] == 50000 and d["scales"]["target_scale"] == 500000
    assert d["interval"] == 20
    assert d["bad_features"] == []
    assert d["tilejson"] == "/tiles/hills/tilejson.json"


def test_unknown_dataset_404(client):
    r = client.get("/datasets/nope")
    assert r.status_code == 404 and r.json()["error"] == "unknown_layer"


def test_same_name_uploaded_twice_makes_a_second_dataset(client):
    # An id made from the name is made unique; only an explicit id that is taken is refused (409).
    body = json.dumps({"type": "FeatureCollection", "features": synthetic_features(seed=4)[:4]})
    headers = {"content-type": "application/geo+json"}
    first = client.post("/datasets?name=Same%20hills", content=body, headers=headers)
    second = client.post("/datasets?name=Same%20hills", content=body, headers=headers)
    assert (first.status_code, second.status_code) == (202, 202), (first.text, second.text)
    assert (first.json()["id"], second.json()["id"]) == ("same-hills", "same-hills-2")
    for ident in ("same-hills", "same-hills-2"):
        assert wait_ready(client, ident)["state"] == "ready"
    assert client.post("/datasets?id=same-hills", content=body, headers=headers).status_code == 409

def test_upload_builds_in_background_then_delete(client):
    feats = synthetic_features(seed=3)[:6]
    feats.append(
        {
            "type": "Feature",
            "properties": {"elevation": 5},
            "geometry": {"type": "Point", "coordinates": [0, 0]},
        }
    )
    body = json.dumps({"type": "FeatureCollection", "features": feats})
    r = client.post(
        "/datasets?id=mine&name=My%20hills", content=body, headers={"content-type": "application/geo+json"}
    )
    assert r.status_code == 202, r.text
    assert r.json()["id"] == "mine" and r.headers["location"] == "/datasets/mine"
    assert any(i["id"] == "mine" for i in client.get("/datasets").json())
    d = wait_ready(client, "mine")
    assert d["state"] == "ready", d
    assert d["counts"]["contours"] == 6 and d["name"] == "My hills"
    assert len(d["bad_features"]) == 1
    # A tile at the centre of the upload's bounds draws the uploaded contours, with their elevations.
    w, s, e, n = d["bounds"]
    tile = client.get("/tiles/mine/{}/{}/{}.mvt".format(*tile_for((w + e) / 2, (s + n) / 2, 12)))
    assert tile.status_code == 200
    uploaded = {f["properties"]["elevation"] for f in feats[:6]}
    assert {f["properties"]["elevation"] for f in check_tile(tile.content)} == uploaded
    again = client.post("/datasets?id=mine", content=body, headers={"content-type": "application/geo+json"})
    assert again.status_code == 409
    assert client.delete("/datasets/mine").status_code == 204
    assert client.get("/datasets/mine").status_code == 404
    assert client.delete("/datasets/mine").status_code == 404
    assert client.get("/datasets/hills").json()["state"] == "ready"
