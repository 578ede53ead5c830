import json
import math

import numpy as np
import pyproj
import pytest

from engine.baselines import simplify_at_scale
from engine.tiles.scale import scale_for_zoom
from tests.app.conftest import LAT0, LON0


def test_feature_collection(client):
    r = client.get("/simplify?scale=250000&dataset=hills")
    assert r.status_code == 200
    assert r.headers["content-type"].startswith("application/geo+json")
    doc = r.json()
    assert doc["type"] == "FeatureCollection" and doc["features"]
    for f in doc["features"]:
        p = f["properties"]
        assert set(p) >= {"elevation", "t", "similarity", "scale"}
        assert p["scale"] == 250000 and 0 <= p["t"] <= 1 and 0 < p["similarity"] <= 1
        for lon, lat in f["geometry"]["coordinates"]:
            assert abs(lon - LON0) < 0.2 and abs(lat - LAT0) < 0.2


@pytest.mark.parametrize("scale", [1, 12_345.6, 50_000, 123_456.7, 500_000, 3e6])
def test_any_positive_scale(client, scale):
    r = client.get(f"/simplify?scale={scale}")
    assert r.status_code == 200
    feats = r.json()["features"]
    if scale <= 50_000:
        assert all(f["properties"]["t"] == 0 for f in feats)


def test_bbox_filter(client):
    every = client.get("/simplify?scale=100000").json()["features"]
    some = client.get(
        f"/simplify?scale=100000&bbox={LON0 + 0.03},{LAT0 + 0.01},{LON0 + 0.05},{LAT0 + 0.03}"
    ).json()
    assert 0 < len(some["features"]) < len(every)


@pytest.mark.parametrize("method", ["ccsm", "dp", "vw", "wm"])
def test_half_zoom_lies_between_in_similarity(client, method):
    """The contours at zoom z + 0.5 lie between those at z and z + 1 in similarity to the input
    (a smaller zoom is a smaller scale: more generalized, less similar)."""
    sims = {}
    for zoom in (10.0, 10.5, 11.0):
        scale = float(scale_for_zoom(zoom, LAT0))
        feats = client.get(f"/simplify?scale={scale}&method={method}").json()["features"]
        sims[zoom] = {f["id"]: f["properties"]["similarity"] for f in feats}
    common = set(sims[10.0]) & set(sims[10.5]) & set(sims[11.0])
    mean = {z: np.mean([sims[z][i] for i in common]) for z in sims}
    assert mean[10.0] - 1e-9 <= mean[10.5] <= mean[11.0] + 1e-9
    if method != "wm":  # WM leaves these smooth synthetic rings alone at both zooms
        assert mean[10.0] < mean[11.0]
    if method == "ccsm":
        for i in common:
            assert sims[10.0][i] - 1e-6 <= sims[10.5][i] <= sims[11.0][i] + 1e-6


def test_original_similarity_is_one(client):
    feats = client.get("/simplify?scale=300000&method=original").json()["features"]
    assert feats and all(math.isclose(f["properties"]["similarity"], 1.0) for f in feats)


@pytest.mark.parametrize("method", ["dp", "wm", "vw", "original"])
def test_each_method_returns_its_own_simplification(client, method):
    scale = 250_000.0
    store = client.app.state.service.store
    to_lonlat = pyproj.Transformer.from_crs(store.dataset("hills").working_crs, "EPSG:4326", always_xy=True)
    # The service runs the baselines at the scale rounded to 1/16 of a zoom level (its cache step).
    snapped = 2.0 ** (round(math.log2(scale) * 16) / 16)
    feats = client.get(f"/simplify?scale={scale}&method={method}").json()["features"]
    assert len(feats) > 5
    recs = {r.fid: r for r in store.load([f["id"] for f in feats])}
    fewer = 0
    for f in feats:
        rec = recs[f["id"]]
        own = rec.original_w if method == "original" else simplify_at_scale(method, rec.original_w, rec.closed, snapped)
        own = np.vstack([own, own[:1]]) if rec.closed else own
        got = np.array(f["geometry"]["coordinates"])
        assert got.shape == own.shape, (f["id"], got.shape, own.shape)
        assert np.abs(got - np.column_stack(to_lonlat.transform(own[:, 0], own[:, 1]))).max() < 1e-6
        fewer += len(own) < len(rec.original_w) + rec.closed
    assert (fewer > 0) == (method != "original")


#: Degrees by which the CLI's file and the route's answer may place a vertex apart: both are the one engine
#: function's result, written to GeoJSON at 7 decimals (about 1 cm), so only the last written digit may differ.
SAME_PLACE_DEG = 2e-7


@pytest.mark.parametrize("scale", [100_000, 250_000])
def test_cli_simplify_is_get_simplify(client, synthetic_path, tmp_path, scale):
    """README: ``ccsm simplify``'s answer is ``GET /simplify``'s. The real CLI on the service's source, at the
    service's scales, writes the same features (ids, properties) with the same geometry as the route returns."""
    from typer.testing import CliRunner

    from app.cli import _register_commands, app

    _register_commands()
    out = tmp_path / "cli.geojson"
    args = ["simplify", str(synthetic_path), "--scale", str(scale), "-o", str(out), "--workers", "1"]
    ran = CliRunner().invoke(app, args)
    assert ran.exit_code == 0, ran.output
    cli = {f["properties"]["id"]: f for f in json.loads(out.read_text())["features"]}
    r = client.get(f"/simplify?dataset=hills&scale={scale}")
    assert r.status_code == 200, r.text
    route = {f["properties"]["id"]: f for f in r.json()["features"]}
    assert len(cli) > 5 and cli.keys() == route.keys()
    for ident, mine in cli.items():
        theirs = route[ident]
        assert mine["properties"] == theirs["properties"], ident
        assert mine["geometry"]["type"] == theirs["geometry"]["type"], ident
        a, b = np.asarray(mine["geometry"]["coordinates"]), np.asarray(theirs["geometry"]["coordinates"])
        assert a.shape == b.shape, (ident, a.shape, b.shape)
        assert np.abs(a - b).max() <= SAME_PLACE_DEG, ident
