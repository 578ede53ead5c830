"""Issue 13: no two contours apart in the input meet as served — in ``simplify`` (what ``ccsm simplify`` and
``GET /simplify`` answer) at any scale from 1:40,000 to 1:1,000,000, in the tiles of every zoom at fractional
zooms, and in the morph tiles' interpolated geometry (docs/design.md section 4.8).

The data are contoured as GDAL's ``gdal_contour`` does, at the levels themselves, so lines of one level touch at
saddle nodes (those pairs may keep touching): two generated integer DEMs (a 10 m interval, and a dense 2 m
interval on a smoother DEM) and two real DEMs the engine was never tuned on (tests/real_dems.py): Maunga Whau
at 1 m on a 10 m grid (lines 10-30 m apart, closer than a pen's width at 1:40,000) and the Coast Mountains
and Howe Sound from matplotlib's topobathy.npz at 50 m, steep land and fjord floors on a 2-arc-minute grid.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pytest
import shapely
from real_dems import write_maunga_whau_contours, write_topobathy_contours
from support.mvt import decode_served
from support.served_topology import (
    LARGEST_SCALE,
    SMALLEST_SCALE,
    input_lines,
    met_in_input,
    morph_drawing,
    new_pairs,
    proper_new_crossings,
    tile_lines,
    zooms_to_check,
)
from synthetic_rasters import fractal_heights, write_exact_level_geojson

from engine.build.datasets import SourceSpec, build_dataset
from engine.ccsm.topology import crossing_pairs
from engine.serve.renderer import Renderer
from engine.serve.simplify import simplify
from engine.store.store import CCSStore
from engine.tiles.grid import tiles_covering
from engine.types import Bounds

pytestmark = pytest.mark.slow


@dataclass(frozen=True)
class ContourData:
    """A contour set to check: how to write it as a GeoJSON file, and what it must hold to be a fair test."""

    write: Callable[[Path], Path]
    min_lines: int
    min_touching: int  # pairs of one level touching at saddle nodes in the input
    min_tiles: int = 21  # tiles x fractions the tile tests look at (the whole of Maunga Whau fits in one tile)
    #: Whether some lines come closer than the quantisation's reach, so that plain rounding draws them crossing.
    lines_within_a_tile_unit: bool = True


def generated(seed: int, beta: float, n: int, interval: float, relief: float) -> Callable[[Path], Path]:
    """A fractal integer DEM (spectral exponent ``beta``, n x n cells of 3 arc-seconds, about 90 m)."""

    def write(path: Path) -> Path:
        heights = fractal_heights(seed, beta, n=n, relief_m=relief)
        return write_exact_level_geojson(path, heights, interval, west=10.0, north=47.0, cell_deg=1 / 1200)

    return write


DATA = {
    "saddle": ContourData(generated(7, 2.5, 56, 10.0, 220.0), min_lines=300, min_touching=5),
    "dense": ContourData(generated(8, 2.9, 40, 2.0, 70.0), min_lines=300, min_touching=5),
    # Real DEMs. Whole-metre heights on a 10 m grid touch at few saddles. The 2-arc-minute topobathy grid puts
    # hardly any node exactly on a 50 m level, so its lines never touch, and its lines (one node per 2.4 km) stay
    # farther apart than the grid's rounding reaches at every zoom checked (at 20 m as well): that set is about
    # long, steep real slopes through simplify and every tile, and shows that snap rounding changes none of them.
    "maunga-whau-1m": ContourData(
        lambda path: write_maunga_whau_contours(path, 1.0), min_lines=150, min_touching=3, min_tiles=18
    ),
    "topobathy-50m": ContourData(
        lambda path: write_topobathy_contours(path, 50.0),
        min_lines=250,
        min_touching=0,
        min_tiles=300,
        lines_within_a_tile_unit=False,
    ),
}


@pytest.fixture(scope="module", params=sorted(DATA))
def served(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> tuple[Renderer, str]:
    folder = tmp_path_factory.mktemp(request.param)
    source = DATA[request.param].write(folder / f"{request.param}.geojson")
    store = CCSStore(folder / "store.sqlite")
    build_dataset(store, SourceSpec(source, request.param, request.param), workers=2)
    return Renderer(store), request.param








def test_the_data_touch_at_saddles_like_gdal_contours(served: tuple[Renderer, str]) -> None:
    renderer, dataset = served
    lines = input_lines(renderer, dataset)
    allowed = met_in_input(renderer, dataset)
    assert len(lines) > DATA[dataset].min_lines
    assert len(allowed) >= DATA[dataset].min_touching  # lines of one level meeting at saddle nodes
    elevation = {c.fid: c.elevation for c in simplify(renderer, dataset, 1.0, method="original").contours}
    assert all(elevation[a] == elevation[b] for a, b in allowed)


def scales_to_check(renderer: Renderer, dataset: str) -> np.ndarray:
    """Log-spaced scales over [1:40,000, 1:1,000,000], plus the middle of every ladder step."""
    ladder = renderer.info(dataset)[0].ladder
    middles = np.sqrt(ladder[:-1] * ladder[1:])
    return np.concatenate([np.geomspace(LARGEST_SCALE, SMALLEST_SCALE, 31), middles])


def test_simplify_leaves_no_new_meeting_pair_at_any_scale(served: tuple[Renderer, str]) -> None:
    renderer, dataset = served
    allowed = met_in_input(renderer, dataset)
    bad = {}
    for scale in scales_to_check(renderer, dataset):
        drawn = simplify(renderer, dataset, float(scale), all_levels=True).contours
        found = {(drawn[a].fid, drawn[b].fid) for a, b in crossing_pairs([c.coords_3857 for c in drawn])}
        if new := new_pairs(found, allowed):
            bad[round(float(scale))] = len(new)
    assert not bad, f"contours apart in the input meet (scale: pairs): {bad}"










#: Tile units two lines must be apart so that plain rounding cannot draw them crossing: rounding to the grid
#: moves a point by up to sqrt(2)/2 units, thinning by up to half a unit (docs/design.md section 4.8).
QUANTISATION_REACH = 2 * (math.sqrt(2) / 2 + 0.5)


def tile_unit_m(renderer: Renderer, z: int) -> float:
    return 2 * 20_037_508.342789244 / (1 << z) / renderer.options.extent


def exact_gaps_m(renderer: Renderer, dataset: str, scale: float, pairs: set[tuple[int, int]]) -> list[float]:
    """Distance, metres in EPSG:3857, between the exact (unquantised) served slices of each pair at a scale."""
    lines = {c.fid: c.coords_3857 for c in simplify(renderer, dataset, scale, all_levels=True).contours}
    return [float(shapely.distance(shapely.linestrings(lines[a]), shapely.linestrings(lines[b]))) for a, b in pairs]


def served_crossings(renderer: Renderer, dataset: str, morph: bool) -> list[tuple[int, float, float, set]]:
    """(z, zoom, scale, pairs apart in the input that cross properly) for every tile and fraction checked,
    in the per-level tiles or in the morph tiles' interpolated geometry."""
    allowed = met_in_input(renderer, dataset)
    bounds = Bounds(*renderer.info(dataset)[0].bounds_3857)
    out = []
    for z, zoom in zooms_to_check(renderer, dataset):
        for tile in tiles_covering(bounds, z):
            drawn_at = zoom + 0.05 if morph else zoom  # the morph between its eighths
            scale = renderer.scale_of_tile(tile, drawn_at)
            if morph:
                lines = morph_lines(renderer, dataset, tile, drawn_at - z)
            else:
                lines = tile_lines(decode_served(renderer.tile(dataset, *tile, zoom=zoom).data).get("contours", {}))
            out.append((z, zoom, scale, proper_new_crossings(lines, allowed)))
    return out


def plain_rounding(renderer: Renderer) -> Renderer:
    """A renderer of the same store that rounds every vertex on its own, as the service did before issue 13."""
    return Renderer(renderer.store, replace(renderer.options, snap_rounding=False))


@pytest.mark.parametrize("morph", [False, True], ids=["tiles", "morph"])
def test_plain_rounding_draws_lines_closer_than_the_grid_crossing(served: tuple[Renderer, str], morph: bool) -> None:
    # What snap rounding is for: with plain rounding, lines apart in the exact served slices (the simplify test
    # above) but closer than the quantisation's reach are drawn crossing on these data. So the test below can
    # fail, and anything beyond that reach would be a crossing the service made by itself.
    renderer, dataset = served
    plain = plain_rounding(renderer)
    checked = crossed = 0
    for z, _zoom, scale, pairs in served_crossings(plain, dataset, morph):
        checked += 1
        if not pairs:
            continue
        crossed += len(pairs)
        gaps = np.array(exact_gaps_m(plain, dataset, scale, pairs)) / tile_unit_m(plain, z)
        assert np.all(gaps > 0), f"z{z} 1:{scale:.0f}: pairs crossing in the exact slices: {sorted(pairs)}"
        assert np.all(gaps < QUANTISATION_REACH), f"z{z} 1:{scale:.0f}: crossing lines {gaps.max():.2f} units apart"
    assert checked >= DATA[dataset].min_tiles
    assert crossed > 0 if DATA[dataset].lines_within_a_tile_unit else crossed == 0
    print(f"{dataset} {'morph' if morph else 'tiles'}: {crossed} pairs crossing on the grid in {checked} tiles")


@pytest.mark.parametrize("morph", [False, True], ids=["tiles", "morph"])
def test_tiles_have_no_proper_new_crossing_at_fractional_zooms(served: tuple[Renderer, str], morph: bool) -> None:
    # Snap rounding in tiles where plain rounding crosses; contours held still in morph tiles where they would
    # meet while morphing (docs/design.md section 4.8). Touching on the grid is allowed, crossing is not.
    renderer, dataset = served
    bad = [(z, zoom, sorted(p)[:3]) for z, zoom, _, p in served_crossings(renderer, dataset, morph) if p]
    assert not bad, f"contours apart in the input cross in served tiles: {bad}"


def morph_lines(renderer: Renderer, dataset: str, tile, f: float) -> dict[int, list[np.ndarray]]:  # type: ignore[no-untyped-def]
    """The contours a morph tile draws at z + f, as docs/morph-tiles.md says a client draws them."""
    return morph_drawing(decode_served(renderer.morph_tile(dataset, *tile).data), tile.z, f)






#: The ccsm-morph plugin's frames per level (web/plugin/src/index.js, stepsPerZoom) and, per tile, how many other
#: fractions are drawn at random: a client may draw a morph tile at any fraction (docs/morph-tiles.md).
PLUGIN_FRAMES, RANDOM_FRACTIONS = 32, 32


def fractions_to_draw(rng: np.random.Generator) -> np.ndarray:
    """The plugin's frames, the middle between each two, and random fractions in [0, 1)."""
    frames = np.arange(PLUGIN_FRAMES) / PLUGIN_FRAMES
    return np.concatenate([frames, frames + 0.5 / PLUGIN_FRAMES, rng.random(RANDOM_FRACTIONS)])


def test_morph_tiles_never_cross_at_any_fraction(served: tuple[Renderer, str]) -> None:
    # Every morph tile drawn as a client draws it at the plugin's 32 frames per level, half-way between them, and
    # at random fractions: no two contours apart in the input cross properly at any of them.
    renderer, dataset = served
    allowed = met_in_input(renderer, dataset)
    bounds = Bounds(*renderer.info(dataset)[0].bounds_3857)
    rng = np.random.default_rng(13)
    drawn = 0
    bad = []
    for z in sorted({z for z, _ in zooms_to_check(renderer, dataset)}):
        for tile in tiles_covering(bounds, z):
            morph = decode_served(renderer.morph_tile(dataset, *tile).data)
            for f in fractions_to_draw(rng):
                lines = morph_drawing(morph, z, float(f))
                drawn += bool(lines)
                if pairs := proper_new_crossings(lines, allowed):
                    bad.append((tile, round(float(f), 4), sorted(pairs)[:3]))
    assert drawn > 200
    assert not bad, f"contours apart in the input cross in a morph tile (tile, fraction, pairs): {bad[:10]}"
