"""``ccsm build`` of a terrain tile source served on loopback: a tile that fails ends with exit status 2 and a
message naming it, and the store is left as it was."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import rasterio
from range_server import serve_folder
from real_dems import MAUNGA_WHAU_ASC
from terrain_pyramids import write_pyramid
from typer.testing import CliRunner

from app.cli import _register_commands, app
from engine.io.dem import read_dem
from engine.io.terrain_tiles import ENCODINGS
from engine.store.store import CCSStore

_register_commands()


def test_nothing_stored_is_touched_when_a_tile_fails(tmp_path: Path) -> None:
    grid = read_dem(MAUNGA_WHAU_ASC)
    pyramid = write_pyramid(
        tmp_path / "p", grid.z.filled(np.nan), rasterio.Affine(*grid.transform), "EPSG:2193", zoom=16,
        encoding=ENCODINGS["mapbox"],
    )
    store = tmp_path / "store.sqlite"
    runner = CliRunner()
    with serve_folder(pyramid.root) as server:
        bbox = ",".join(f"{v:.6f}" for v in pyramid.bbox)
        src = f"mapbox:{server.url}/{{z}}/{{x}}/{{y}}.png"
        ok = runner.invoke(app, ["build", src, "--bbox", bbox, "--dem-zoom", "16", "--interval", "10",
                                 "--store", str(store), "--id", "mw", "--workers", "1"])
        assert ok.exit_code == 0, ok.output
        before = CCSStore(store, readonly=True).dataset("mw")
        store_bytes = store.read_bytes()
        shutil.rmtree(pyramid.root / "16" / str(pyramid.tiles[-1][1]))
        fresh_cache = {"XDG_CACHE_HOME": str(tmp_path / "fresh")}  # the first build's tiles are not in it
        for args in (["--interval", "5"], ["--interval", "5", "--id", "other"]):
            bad = runner.invoke(app, ["build", src, "--bbox", bbox, "--dem-zoom", "16", "--store", str(store),
                                      "--workers", "1", "--id", "mw", *args], env=fresh_cache)
            assert bad.exit_code == 2, bad.output
            assert "HTTP 404" in bad.output and f"16/{pyramid.tiles[-1][1]}/" in bad.output
    after = CCSStore(store, readonly=True)
    assert after.dataset_ids() == ["mw"]
    now = after.dataset("mw")
    assert (now.source_hash, now.data_version, now.n_contours) == (
        before.source_hash, before.data_version, before.n_contours
    )
    after.close()
    assert store.read_bytes() == store_bytes
