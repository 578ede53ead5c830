"""Issue 24: any terrain, no crash. Generated terrain (tests/terrain_strategies.py) and real DEMs no one here
tuned for (tests/real_dems.py) go through the whole pipeline: build, tiles at every zoom from 1:1,000,000 to
1:40,000 at three fractions of a level, morph tiles, labels, ``simplify`` (what ``GET /simplify`` answers) at
five scales and ``ccsm export``. Asserted: no exception anywhere, and the product's invariants:

- zero new crossings (contours apart in the input never meet in simplify, tiles or morph tiles; the checkers of
  tests/engine/serve/test_served_topology.py);
- t = 0 at the source scale and at every larger scale;
- similarity never rising as the scale gets smaller, contour by contour;
- feature ids stable across zooms (every id served is a stored contour's, with that contour's elevation);
- labels on their line (within the placement's drift bound of the line as drawn where they first show).

CI runs the ``ci`` hypothesis profile (derandomized, a fixed budget); ``CCSM_HYPOTHESIS_PROFILE=nightly`` runs
many more examples (README, "Tests").
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import shapely
from hypothesis import example, given
from real_dems import (
    luxembourg_dem,
    write_dem_window,
    write_glacier_dem,
    write_maunga_whau_contours,
    write_rocky_mountains_dem,
    write_topobathy_contours,
)
from support.mvt import decode_served as decode
from support.served_topology import (
    LARGEST_SCALE,
    SMALLEST_SCALE,
    met_in_input,
    morph_drawing,
    new_pairs,
    proper_new_crossings,
    tile_lines,
    zooms_to_check,
)
from terrain_strategies import TERRAIN_SETTINGS, TerrainCase, terrains
from typer.testing import CliRunner

from app.cli import _register_commands, app
from engine.build.datasets import SourceSpec, build_dataset
from engine.cartography.labels import LabelStyle, metres_per_px
from engine.cartography.options import CartographyOptions
from engine.ccsm.topology import crossing_pairs
from engine.errors import SourceError
from engine.io.dem import DEM_SUFFIXES
from engine.io.sample import sample_dem_path
from engine.serve.renderer import Renderer
from engine.serve.simplify import simplify
from engine.store.store import CCSStore
from engine.tiles.grid import tiles_covering
from engine.tiles.scale import scale_for_zoom
from engine.types import Bounds

pytestmark = pytest.mark.slow

_register_commands()
DATASET = "terrain"
SOURCE_SCALE = 50_000.0
#: Five scales of simplify: larger than the source scale, the source scale, two between, the smallest checked.
SIMPLIFY_SCALES = (LARGEST_SCALE, SOURCE_SCALE, 120_000.0, 400_000.0, SMALLEST_SCALE)
#: Morph tiles drawn at these fractions of their level (the plugin draws any fraction in [0, 1)).
MORPH_FRACTIONS = (0.0, 0.3, 0.7, 0.97)
#: How much one contour's similarity may rise from one scale to a smaller one (see check_simplify).
PER_CONTOUR_RISE = 0.02


@dataclass
class Served:
    """A built dataset and what it was built from."""

    renderer: Renderer
    store_path: Path
    allowed: set[tuple[int, int]]  # pairs meeting in the input (touching at saddles): allowed to keep meeting
    elevation: dict[int, float]  # of every stored contour, by fid


def build(source: Path, interval: float, units: str, folder: Path) -> Served | None:
    """Build ``source`` into a fresh store; None when it holds no contour at all (nothing to serve)."""
    store = CCSStore(folder / "store.sqlite")
    is_dem = source.suffix.lower() in DEM_SUFFIXES
    spec = SourceSpec(
        source,
        DATASET,
        DATASET,
        interval=interval if is_dem else None,
        source_scale=SOURCE_SCALE,
        cartography=CartographyOptions(units=units),
    )
    try:
        info, _ = build_dataset(store, spec, workers=1)
    except SourceError as exc:
        # Refusing a source with no usable contour is an answer, not a crash: each feature is named with why
        # (e.g. a lon/lat line past +180 degrees, which the reader does not wrap).
        assert "no usable contour among" in str(exc) and ": " in str(exc), exc
        return None
    if info.n_contours == 0:
        return None
    assert all(bad.get("reason") for bad in info.bad_features), "a contour left out without a reason"
    renderer = Renderer(store)
    original = simplify(renderer, DATASET, 1.0, method="original", all_levels=True).contours
    return Served(
        renderer, folder / "store.sqlite", met_in_input(renderer, DATASET), {c.fid: c.elevation for c in original}
    )


def check_simplify(served: Served) -> None:
    """t = 0 up to the source scale, similarity never rising as the scale gets smaller, no new meeting pair."""
    previous: dict[int, float] = {}
    for scale in SIMPLIFY_SCALES:
        drawn = simplify(served.renderer, DATASET, scale, all_levels=True).contours
        assert {c.fid for c in drawn} <= set(served.elevation)
        if scale <= SOURCE_SCALE:
            assert all(c.t == 0.0 for c in drawn), f"t > 0 at 1:{scale:.0f}"
        sims = {c.fid: c.similarity for c in drawn}
        common = sorted(set(sims) & set(previous))
        if common:
            before, now = np.array([previous[f] for f in common]), np.array([sims[f] for f in common])
            # The mean never rises (README, Fig. 10). One contour's improved Frechet distance to L0 is not
            # monotone in t by construction, so it may rise a little: 0.0066 on the "feet" example below, against
            # a per-level method's typical jump of 0.09.
            assert now.mean() <= before.mean() + 1e-9, f"mean similarity rises at 1:{scale:.0f}"
            assert np.all(now <= before + PER_CONTOUR_RISE), f"a contour's similarity jumps up at 1:{scale:.0f}"
        previous = sims
        found = {(drawn[a].fid, drawn[b].fid) for a, b in crossing_pairs([c.coords_3857 for c in drawn])}
        assert not new_pairs(found, served.allowed), f"contours apart in the input meet at 1:{scale:.0f}"


def check_served_ids(served: Served, layer: dict, where: str) -> None:
    """Every feature served is a stored contour, drawn with that contour's elevation (ids stable across zooms)."""
    for feature in layer.get("features", []):
        fid = feature["id"]
        assert fid in served.elevation, f"{where}: unknown id {fid}"
        assert feature["properties"]["elevation"] == pytest.approx(served.elevation[fid]), f"{where}: id {fid}"


def check_tiles(served: Served) -> int:
    """Tiles at every zoom and three fractions, and morph tiles drawn at several fractions: no new crossing,
    ids stable. Returns how many non-empty tiles were looked at."""
    renderer = served.renderer
    bounds = Bounds(*renderer.info(DATASET)[0].bounds_3857)
    seen = 0
    for z, zoom in zooms_to_check(renderer, DATASET):
        for tile in tiles_covering(bounds, z):
            layer = decode(renderer.tile(DATASET, *tile, zoom=zoom).data).get("contours", {})
            check_served_ids(served, layer, f"tile {tuple(tile)} at {zoom}")
            assert not proper_new_crossings(tile_lines(layer), served.allowed), f"crossing in {tuple(tile)} at {zoom}"
            seen += bool(layer)
            if zoom != z:
                continue
            morph = decode(renderer.morph_tile(DATASET, *tile).data)
            if morph:
                check_served_ids(served, morph["contours"], f"morph tile {tuple(tile)}")
            for f in MORPH_FRACTIONS:
                lines = morph_drawing(morph, z, f)
                assert not proper_new_crossings(lines, served.allowed), f"crossing in morph {tuple(tile)} at {f}"
            decode(renderer.label_layer.layer(DATASET, tile))  # the label layer of a tile is served and decodes
    return seen


def check_labels(served: Served) -> None:
    """Each label names a stored contour's elevation and sits on that contour as drawn where it first shows
    (the placement's drift bound, plus a pixel for the interpolation between the ladder's slices)."""
    labels = served.renderer.labels(DATASET)
    if len(labels) == 0:
        return
    info = served.renderer.info(DATASET)[0]
    lat = float(np.degrees(np.arctan(np.sinh((info.bounds_3857[1] + info.bounds_3857[3]) / 2 / 6378137.0))))
    elevations = np.array([served.elevation[int(f)] for f in labels.fid])
    assert np.allclose(labels.elevation, elevations), "a label names another contour's elevation"
    bound_px = LabelStyle().max_drift_px + 1.0
    for zoom in np.unique(labels.min_zoom).tolist():
        drawn = simplify(served.renderer, DATASET, float(scale_for_zoom(zoom, lat)), all_levels=True).contours
        lines = {c.fid: c.coords_3857 for c in drawn}
        at_zoom = np.flatnonzero(labels.min_zoom == zoom)
        for fid, xy in zip(labels.fid[at_zoom].tolist(), labels.xy[at_zoom], strict=True):
            if fid not in lines:
                continue  # not drawn at that scale (too small): the tiles do not show its label either
            gap = shapely.distance(shapely.Point(xy), shapely.LineString(lines[fid])) / float(metres_per_px(zoom))
            assert gap <= bound_px, f"label of {fid} {gap:.1f} px off its line at z{zoom}"


def check_export(served: Served, folder: Path) -> None:
    """``ccsm export`` of the stored dataset over the zooms checked writes an archive and exits 0."""
    zs = sorted({z for z, _ in zooms_to_check(served.renderer, DATASET)})
    out = folder / "terrain.pmtiles"
    args = ["export", "--store", served.store_path, "--dataset", DATASET, "-o", out]
    args += ["--minzoom", zs[0], "--maxzoom", zs[-1], "--workers", 1]
    result = CliRunner().invoke(app, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    assert out.stat().st_size > 0


def whole_pipeline(source: Path, interval: float, units: str, folder: Path) -> Served | None:
    """Every step on one source; returns the built dataset (None: the source held no contour)."""
    served = build(source, interval, units, folder)
    if served is None:
        return None
    check_simplify(served)
    check_tiles(served)
    check_labels(served)
    check_export(served, folder)
    return served


@TERRAIN_SETTINGS
@given(case=terrains())
@example(case=TerrainCase("tiny-everything", seed=3, n=40, place="lonlat-arctic", as_lines=False))
@example(case=TerrainCase("feet", seed=16, n=49, place="lonlat-antarctic", as_lines=False))  # a contour's Sim rises
# Centimetre rings of an index level at 1" on the equator: their first label zoom lies past the last zoom.
@example(case=TerrainCase("tiny-everything", seed=3, n=40, place="lonlat-equator", as_lines=False))
# Found by the nightly profile: every line of this DEM past +180 degrees or degenerate; refused with reasons.
@example(case=TerrainCase("one-long-contour", seed=2, n=40, place="lonlat-antimeridian-east", as_lines=False))
def test_any_generated_terrain_goes_through_the_whole_pipeline(case: TerrainCase, tmp_path_factory) -> None:  # type: ignore[no-untyped-def]
    folder = tmp_path_factory.mktemp("terrain")
    whole_pipeline(case.write(folder), case.interval, case.units, folder)


def test_whole_pipeline_checks_see_something(tmp_path: Path) -> None:
    # The checks above are not vacuous: on ordinary hills they look at tiles, morph tiles and labels.
    case = TerrainCase("few-levels", seed=1, n=60, place="utm-33n", as_lines=False)
    served = whole_pipeline(case.write(tmp_path), 50.0, "m", tmp_path)
    assert served is not None and len(served.elevation) > 30
    assert check_tiles(served) > 10
    assert len(served.renderer.labels(DATASET)) > 0


#: Real terrain no one here tuned for (tests/real_dems.py, tests/data/README.md): how to write each as a source
#: file (its name's suffix says which kind), and the interval (metres) fitting its relief.
REAL_TERRAIN: dict[str, tuple[str, Callable[[Path], Path], float]] = {
    # Ridges and valleys of the Cumberland Plateau (the bundled sample's DEM, USGS, public domain), 5 km a side.
    "jacksboro-ridges": (
        ".tif",
        lambda p: write_dem_window(sample_dem_path(), (slice(140, 200), slice(170, 230)), p),
        20.0,
    ),
    # Coast with bathymetry: Howe Sound's fjord floor to the Coast Mountains (matplotlib's topobathy.npz).
    "howe-sound-coast": (
        ".geojson",
        lambda p: write_topobathy_contours(p, 100.0, (slice(64, 76), slice(84, 96))),
        100.0,
    ),
    # A volcano: Maunga Whau's cone and crater (R's volcano via vega-datasets, tests/data).
    "maunga-whau-volcano": (".geojson", lambda p: write_maunga_whau_contours(p, 2.0), 2.0),
    # A dissected plateau with a ragged nodata border: Luxembourg's north (R's terra, ex/elev.tif, SRTM).
    "luxembourg-plateau": (
        ".tif",
        lambda p: write_dem_window(luxembourg_dem(), (slice(0, 30), slice(20, 50)), p),
        25.0,
    ),
    # High mountains: the Front Range, 1,700-4,300 m on PRISM's 4 km grid (R's fields, RMelevation).
    "rockies-front-range": (".tif", lambda p: write_rocky_mountains_dem(p, (slice(124, 134), slice(124, 134))), 200.0),
    # A glacier: Franke's glacier (R's fields), gridded from its digitized contours, nodata outside them.
    "franke-glacier": (".tif", write_glacier_dem, 50.0),
}


@pytest.mark.parametrize("name", sorted(REAL_TERRAIN))
def test_real_terrain_goes_through_the_whole_pipeline(name: str, tmp_path: Path) -> None:
    suffix, write, interval = REAL_TERRAIN[name]
    served = whole_pipeline(write(tmp_path / f"{name}{suffix}"), interval, "m", tmp_path)
    assert served is not None and len(served.elevation) >= 10, "a real terrain with hardly any contour"
