"""Issue 10, every failure a clear answer: uploads that gave 500 (or were accepted and then unservable) now get
a 4xx naming the feature, or list it among the bad features; logs cannot be forged through input."""

from __future__ import annotations

import json
import logging

import pytest

from tests.app.conftest import synthetic_features

GEOJSON = {"content-type": "application/geo+json"}
GOOD = synthetic_features(seed=9)[:3]


def feature(fid, elevation, coords):
    return {
        "type": "Feature",
        "properties": {"id": fid, "elevation": elevation},
        "geometry": {"type": "LineString", "coordinates": coords},
    }


def fc(*feats):
    return json.dumps({"type": "FeatureCollection", "features": list(feats)})


def wait_built(client, ident):
    client.app.state.service.wait_for_builds(120)
    return client.get(f"/datasets/{ident}")


ONE_POINT = feature("lonely", 400, [[-84.25, 36.6]])
HUGE_UP = feature("sky", 1e308, [[-84.25, 36.6], [-84.24, 36.61]])
HUGE_DOWN = feature("abyss", -1e308, [[-84.26, 36.6], [-84.25, 36.62]])
POLAR = feature("pole", 400, [[10.0, 87.0], [11.0, 87.5], [12.0, 88.0]])


@pytest.mark.parametrize(
    ("feats", "names"),
    [
        ([ONE_POINT], ["lonely", "2 points"]),
        ([HUGE_UP, HUGE_DOWN], ["sky", "abyss", "1e+308"]),
        ([POLAR], ["pole", "Web Mercator"]),
    ],
)
def test_issue_10_unusable_features_alone_give_400_naming_them(client, feats, names):
    r = client.post("/datasets?id=bad", content=fc(*feats), headers=GEOJSON)
    assert r.status_code == 400, r.text
    for word in names:
        assert word in r.json()["detail"], r.json()
    assert client.get("/datasets/bad").status_code == 404


@pytest.mark.parametrize(
    ("bad", "reason"),
    [(ONE_POINT, "2 points"), (HUGE_UP, "1e+308"), (POLAR, "Web Mercator")],
)
def test_issue_10_unusable_features_among_good_ones_are_listed(client, bad, reason):
    r = client.post("/datasets?id=mixed", content=fc(*GOOD, bad), headers=GEOJSON)
    assert r.status_code == 202, r.text
    listed = r.json()["bad_feature_list"]
    assert [b["id"] for b in listed] == [bad["properties"]["id"]] and reason in listed[0]["reason"]
    d = wait_built(client, "mixed")
    assert d.status_code == 200, d.text
    body = d.json()
    assert body["state"] == "ready" and body["counts"]["contours"] == 3
    assert body["interval"] is None or body["interval"] < 1e6
    assert [b["id"] for b in body["bad_features"]] == [bad["properties"]["id"]]
    w, s, e, n = body["bounds"]
    assert -85.06 < s < n < 85.06


def test_issue_10_deeply_nested_json_is_400(client):
    r = client.post("/datasets?id=deep", content=b"[" * 100_000 + b"]" * 100_000, headers=GEOJSON)
    assert r.status_code == 400, r.text
    assert "nested" in r.json()["detail"]


def test_issue_10_non_ascii_name_gives_an_ascii_id(client):
    r = client.post("/datasets?name=H%C3%BCgel%20%E5%B1%B1%20Nord", content=fc(*GOOD), headers=GEOJSON)
    assert r.status_code == 202, r.text
    ident = r.json()["id"]
    assert ident == "hugel-nord" and r.headers["location"] == "/datasets/hugel-nord"
    assert r.json()["name"] == "Hügel 山 Nord"
    only_other_script = client.post("/datasets?name=%E5%B1%B1", content=fc(*GOOD), headers=GEOJSON)
    assert only_other_script.status_code == 202, only_other_script.text
    assert only_other_script.json()["id"].isascii()
    assert wait_built(client, ident).json()["state"] == "ready"


def test_issue_10_feature_ids_cannot_forge_log_lines(client, caplog):
    forged = "x\n2026-01-01 00:00:00 ERROR ccsm.app: forged line\x1b[31m"
    caplog.set_level(logging.INFO)
    r = client.post("/datasets?id=forge", content=fc(feature(forged, 400, [[-84.25, 36.6]])), headers=GEOJSON)
    assert r.status_code == 400
    logged = [rec.getMessage() for rec in caplog.records if rec.name.startswith("ccsm")]
    assert any("forged line" in m for m in logged), logged  # the id is logged...
    for message in logged:
        assert "\n" not in message and "\x1b" not in message, message  # ...on one line, escapes shown
