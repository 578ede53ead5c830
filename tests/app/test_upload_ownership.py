"""Issue 10, uploads owned and safe: who may write, in which form, and ids that cannot be taken twice.

Each test here failed on main before the fix: writes were anonymous, a text/plain body was taken, ten
simultaneous uploads of one id all got 202, a building or failed dataset could not be deleted.
"""

from __future__ import annotations

import json
import time
from concurrent.futures import ThreadPoolExecutor

import httpx
import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from engine.store.store import CCSStore
from tests.app.conftest import LiveServer, make_settings, synthetic_features

GEOJSON = {"content-type": "application/geo+json"}
BODY = json.dumps({"type": "FeatureCollection", "features": synthetic_features(seed=4)[:3]})


def _client(tmp_path, built_store, synthetic_path, *, client=("127.0.0.1", 50000), base="http://localhost", **kw):
    store = tmp_path / "ccsm.sqlite"
    CCSStore(built_store)._con().execute("PRAGMA wal_checkpoint(TRUNCATE)")
    store.write_bytes(built_store.read_bytes())
    app = create_app(make_settings(store, [synthetic_path], build_workers=1, **kw))
    return TestClient(app, base_url=base, client=client)


def test_issue_10_remote_writes_are_refused_without_a_token(tmp_path, built_store, synthetic_path):
    with _client(tmp_path, built_store, synthetic_path, client=("203.0.113.9", 4000)) as c:
        up = c.post("/datasets?id=remote", content=BODY, headers=GEOJSON)
        assert up.status_code == 403 and "CCSM_ADMIN_TOKEN" in up.json()["detail"], up.text
        gone = c.delete("/datasets/hills")
        assert gone.status_code == 403, gone.text
        assert [d["id"] for d in c.get("/datasets").json()] == ["hills"]


def test_issue_10_local_client_must_address_the_server_as_localhost(tmp_path, built_store, synthetic_path):
    # A page whose own name resolves to 127.0.0.1 (DNS rebinding) sends its own Host: refused.
    with _client(tmp_path, built_store, synthetic_path, base="http://evil.example:8000") as c:
        r = c.post("/datasets?id=rebound", content=BODY, headers=GEOJSON)
        assert r.status_code == 403 and "localhost" in r.json()["detail"], r.text
        assert c.delete("/datasets/hills").status_code == 403


@pytest.mark.parametrize(
    ("content_type", "hint"),
    [
        ("text/plain", "application/geo+json"),
        ("application/x-www-form-urlencoded", "application/geo+json"),
        ("multipart/form-data; boundary=x", "--data-binary"),
        (None, "(none)"),
    ],
)
def test_issue_10_simple_content_types_are_refused(tmp_path, built_store, synthetic_path, content_type, hint):
    # These are the bodies a web page may send cross-site without a preflight: never a write.
    headers = {"content-type": content_type} if content_type else {}
    with _client(tmp_path, built_store, synthetic_path) as c:
        r = c.post("/datasets?id=plain", content=BODY, headers=headers)
        assert r.status_code == 415, r.text
        assert hint in r.json()["detail"]
        assert [d["id"] for d in c.get("/datasets").json()] == ["hills"]


def test_issue_10_cross_site_preflight_of_a_write_is_not_granted(tmp_path, built_store, synthetic_path):
    with _client(tmp_path, built_store, synthetic_path) as c:
        for method in ("POST", "DELETE"):
            r = c.options(
                "/datasets",
                headers={"origin": "https://elsewhere.example", "access-control-request-method": method},
            )
            assert method not in r.headers.get("access-control-allow-methods", ""), r.headers


def test_issue_10_token_is_required_when_set(tmp_path, built_store, synthetic_path):
    with _client(tmp_path, built_store, synthetic_path, admin_token="s3cret-token") as c:
        missing = c.post("/datasets?id=tok", content=BODY, headers=GEOJSON)
        assert missing.status_code == 401 and missing.headers["www-authenticate"].startswith("Bearer")
        wrong = c.post("/datasets?id=tok", content=BODY, headers={**GEOJSON, "authorization": "Bearer nope"})
        assert wrong.status_code == 401
        assert c.delete("/datasets/hills").status_code == 401  # loopback is no excuse once a token is set
        assert c.get("/datasets/hills").json()["state"] == "ready"
        auth = {**GEOJSON, "authorization": "Bearer s3cret-token"}
        ok = c.post("/datasets?id=tok", content=BODY, headers=auth)
        assert ok.status_code == 202, ok.text
        assert c.delete("/datasets/tok", headers={"authorization": "Bearer s3cret-token"}).status_code == 204


def _post_many(url: str, n: int, query: str) -> list[httpx.Response]:
    def post(_: int) -> httpx.Response:
        return httpx.post(f"{url}/datasets?{query}", content=BODY, headers=GEOJSON, timeout=60)

    with ThreadPoolExecutor(n) as pool:
        return list(pool.map(post, range(n)))


@pytest.fixture()
def two_servers(tmp_path, built_store, synthetic_path):
    """Two `ccsm serve` processes on one store file."""
    store = tmp_path / "ccsm.sqlite"
    CCSStore(built_store)._con().execute("PRAGMA wal_checkpoint(TRUNCATE)")
    store.write_bytes(built_store.read_bytes())
    env = {
        "CCSM_STORE_PATH": str(store),
        "CCSM_SOURCES": str(synthetic_path),
        "CCSM_BUILD_WORKERS": "1",
        "CCSM_BUILD_QUEUE": "20",
    }
    servers = [LiveServer(env, log=tmp_path / f"server{i}.log") for i in range(2)]
    try:
        for s in servers:
            s.wait_healthy()
        yield servers
    finally:
        for s in servers:
            s.stop()


def test_issue_10_ten_simultaneous_uploads_of_one_id_one_wins(two_servers):
    a, b = two_servers
    answers = _post_many(a.url, 10, "id=race1")
    assert sorted(r.status_code for r in answers) == [202] + [409] * 9, [r.text for r in answers]
    # Across two processes on one store too.
    with ThreadPoolExecutor(2) as pool:
        both = list(pool.map(lambda s: _post_many(s.url, 5, "id=race2"), (a, b)))
    codes = sorted(r.status_code for rs in both for r in rs)
    assert codes == [202] + [409] * 9, codes


def test_issue_10_same_name_uploads_get_distinct_ids(two_servers):
    a, b = two_servers
    with ThreadPoolExecutor(2) as pool:
        both = list(pool.map(lambda s: _post_many(s.url, 5, "name=Twin%20hills"), (a, b)))
    answers = [r for rs in both for r in rs]
    assert all(r.status_code == 202 for r in answers), [r.text for r in answers]
    ids = sorted(r.json()["id"] for r in answers)
    assert ids == sorted(["twin-hills"] + [f"twin-hills-{n}" for n in range(2, 11)])
    for ident in ids:
        a.wait_ready(ident, timeout=240)
    listed = {d["id"]: d for d in httpx.get(a.url + "/datasets").json()}
    assert all(listed[i]["state"] == "ready" for i in ids)


def _big_body(n_sets: int = 6) -> str:
    feats = []
    for seed in range(n_sets):
        for f in synthetic_features(seed=seed):
            f = json.loads(json.dumps(f))
            f["properties"]["id"] = f"s{seed}-{f['properties']['id']}"
            f["geometry"]["coordinates"] = [[x + 0.2 * seed, y] for x, y in f["geometry"]["coordinates"]]
            feats.append(f)
    return json.dumps({"type": "FeatureCollection", "features": feats})


def test_issue_10_delete_of_a_building_dataset_stays_deleted(live):
    r = httpx.post(live.url + "/datasets?id=doomed", content=_big_body(), headers=GEOJSON, timeout=60)
    assert r.status_code == 202, r.text
    assert httpx.get(live.url + "/datasets/doomed").json()["state"] == "building"
    gone = httpx.delete(live.url + "/datasets/doomed")
    assert gone.status_code == 204, gone.text
    # Long enough for the build to have finished had it gone on (it takes a few seconds).
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        assert httpx.get(live.url + "/datasets/doomed").status_code == 404
        assert "doomed" not in {d["id"] for d in httpx.get(live.url + "/datasets").json()}
        time.sleep(0.5)
    # The id is free again.
    again = httpx.post(live.url + "/datasets?id=doomed", content=BODY, headers=GEOJSON, timeout=120)
    assert again.status_code == 202, again.text
    assert live.wait_ready("doomed")["state"] == "ready"
    assert httpx.delete(live.url + "/datasets/doomed").status_code == 204


def test_issue_10_failed_dataset_can_be_deleted_and_uploaded_again(client):
    store = client.app.state.service.store
    store.set_build_status("broken", "failed", 0, 0, "the build was interrupted")
    assert client.get("/datasets/broken").json()["state"] == "failed"
    ready = client.get("/readyz")
    assert ready.status_code == 503 and "'broken' failed to build" in " ".join(ready.json()["problems"])
    assert client.post("/datasets?id=broken", content=BODY, headers=GEOJSON).status_code == 409
    assert client.delete("/datasets/broken").status_code == 204
    assert client.get("/datasets/broken").status_code == 404
    r = client.post("/datasets?id=broken", content=BODY, headers=GEOJSON)
    assert r.status_code == 202, r.text
    building = client.get("/readyz").json()["problems"]
    client.app.state.service.wait_for_builds(120)
    assert client.get("/datasets/broken").json()["state"] == "ready"
    assert client.get("/readyz").status_code == 200, building


def test_issue_10_deleted_configured_source_does_not_show_building(client):
    assert client.delete("/datasets/hills").status_code == 204
    assert client.get("/datasets").json() == []
    assert client.get("/datasets/hills").status_code == 404
    assert client.get("/readyz").status_code == 200


def test_issue_10_build_queue_is_bounded(tmp_path, built_store, synthetic_path):
    big = _big_body(3)
    with _client(tmp_path, built_store, synthetic_path, max_builds=1, build_queue=1) as c:
        codes = [c.post(f"/datasets?id=q{i}", content=big, headers=GEOJSON) for i in range(3)]
        assert [r.status_code for r in codes] == [202, 202, 429], [r.text for r in codes]
        assert int(codes[2].headers["retry-after"]) > 0
        assert "CCSM_MAX_BUILDS" in codes[2].json()["detail"]
        assert c.get("/datasets/q2").status_code == 404  # the refused upload left nothing behind
        assert not list((tmp_path / "uploads").glob("q2-*"))
        c.app.state.service.wait_for_builds(240)
        assert [c.get(f"/datasets/q{i}").json()["state"] for i in range(2)] == ["ready", "ready"]
        again = c.post("/datasets?id=q2", content=big, headers=GEOJSON)
        assert again.status_code == 202, again.text
        c.app.state.service.wait_for_builds(240)
