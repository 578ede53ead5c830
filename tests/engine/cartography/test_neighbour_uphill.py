"""Labels of contour files read uphill, the side of higher ground read off the neighbouring levels
(engine/cartography/neighbour_uphill.py; docs/design.md section 9.3): checked against the DEM on either side of
each label, on generated terrain (hypothesis, tests/terrain_strategies.py) and on a real DEM's contours written
as a contour file whose lines run either way."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyproj
import pytest
import rasterio
from hypothesis import given, settings
from hypothesis import strategies as st
from real_dems import MAUNGA_WHAU_ASC
from scipy import ndimage
from terrain_strategies import TerrainCase, terrains

from engine.build.datasets import SourceSpec, build_dataset
from engine.cartography.labels import UPSIDE_DOWN_LIMIT_DEG, upright_angle
from engine.cartography.neighbour_uphill import nearest_crossed, text_top, top_uphill
from engine.cartography.options import CartographyOptions
from engine.io.dem import contours_from_dem, read_dem
from engine.io.dem_tracing import LEVEL_OFFSET, iter_levels
from engine.store.store import CCSStore

#: Metres per cell the generated grids are laid out at (the probes' start and reach are in metres).
CELL_M = 10.0


@settings(max_examples=25, deadline=None)
@given(case=terrains(max_side=60), offset=st.floats(0.02, 0.2))
def test_the_side_of_higher_ground_is_the_dem_s_on_generated_terrain(case: TerrainCase, offset: float) -> None:
    z = np.ma.masked_invalid(case.heights().astype(np.float64))
    if z.count() < 16 or np.ptp(z.compressed()) < 2 * case.interval:
        return
    levels = np.arange(np.ceil(z.min() / case.interval) * case.interval, z.max(), case.interval)
    lines, heights = [], []
    # Traced a millimetre above each level, as the DEM reader does (a node exactly at a level makes no line).
    for level, traced in iter_levels(z, levels + LEVEL_OFFSET):
        for line in traced:
            lines.append(line * CELL_M)
            heights.append(level)
    xy, angle, own = [], [], []
    for line, level in zip(lines, heights, strict=True):
        # A label where the line runs straight (as labels are placed), along it, upright.
        d = np.diff(line, axis=0)
        heading = np.arctan2(d[:, 1], d[:, 0])
        turn = np.abs((np.diff(heading) + np.pi) % (2 * np.pi) - np.pi)
        straight = np.flatnonzero(turn < np.radians(10.0)) + 1
        # not at a grid node (a vertex of a level the node nearly has): there the bilinear DEM of the check and
        # the tracer's heights, linear along cell edges, can see higher ground on both sides
        cells = line[straight] / CELL_M
        straight = straight[np.hypot(*(cells - np.round(cells)).T) > 0.05]
        if len(straight):
            k = int(straight[len(straight) // 2])
            dx, dy = line[k + 1] - line[k - 1]
            xy.append(line[k])
            angle.append(float(upright_angle(np.array([dx]), np.array([dy]))[0]))
            own.append(level)
    if not xy:
        return
    xy_a, angle_a, own_a = np.array(xy), np.array(angle), np.array(own)
    signs = top_uphill(xy_a, angle_a, own_a, lines, np.array(heights))
    # The DEM a fraction of a cell toward each label's top and foot (grid index space: x column, y row), near
    # enough that bilinear heights and the tracer's (linear along cell edges) agree on the side.
    step = text_top(angle_a) * offset * CELL_M
    filled = z.filled(np.nan)

    def dem(points: np.ndarray) -> np.ndarray:
        col, row = points[:, 0] / CELL_M, points[:, 1] / CELL_M
        return ndimage.map_coordinates(filled, [row, col], order=1, mode="nearest", cval=np.nan)

    top, foot = dem(xy_a + step), dem(xy_a - step)
    diff = top - foot
    # Checked where the DEM has the label's level between its two sides (in a saddle cell the bilinear DEM and
    # the tracer's cell-by-cell choice can see the same side of the level on both), and where the ground between
    # the label and the first line each probe meets is known: lines alone cannot tell a probe that passes a
    # hole of nodata (a line beyond it need not be a neighbour of the label's).
    holes = np.isnan(filled).astype(np.float64)

    def crosses_nodata(direction: np.ndarray) -> np.ndarray:
        _, far = nearest_crossed(xy_a, direction, lines, np.array(heights))
        reach = np.minimum(far, np.hypot(*filled.shape) * CELL_M)
        out = np.zeros(len(xy_a), dtype=bool)
        for k in range(len(xy_a)):
            along = np.arange(0.0, reach[k] + CELL_M / 4, CELL_M / 4)
            points = (xy_a[k] + along[:, None] * direction[k]) / CELL_M
            inside = (points >= 0).all(axis=1) & (points <= np.array(filled.shape[::-1]) - 1).all(axis=1)
            wet = ndimage.map_coordinates(holes, [points[inside, 1], points[inside, 0]], order=1)
            out[k] = bool((wet > 0).any())
        return out

    known = ~(crosses_nodata(text_top(angle_a)) | crosses_nodata(-text_top(angle_a)))
    told = (signs != 0) & np.isfinite(diff) & ((top - own_a) * (foot - own_a) < 0) & known
    assert (np.sign(diff[told]) == signs[told]).all(), (case, diff[told], signs[told])
    if len(set(heights)) >= 3 and len(xy) >= 4:
        assert (signs != 0).any()  # neighbour levels tell some labels (a small ring's probe meets itself first)


TO_2193 = pyproj.Transformer.from_crs("EPSG:3857", "EPSG:2193", always_xy=True)


def maunga_whau_contours_file(folder: Path, seed: int) -> Path:
    """Maunga Whau's 5 m contours as a GeoJSON contour file (EPSG:2193), every line's direction drawn at random."""
    traced = contours_from_dem(MAUNGA_WHAU_ASC, interval=5.0)
    rng = np.random.default_rng(seed)
    features = []
    for c in traced.contours:
        coords = np.vstack([c.coords, c.coords[:1]]) if c.closed else np.asarray(c.coords)
        if rng.random() < 0.5:
            coords = coords[::-1]
        features.append(
            {
                "type": "Feature",
                "properties": {"ele": c.elevation},
                "geometry": {"type": "LineString", "coordinates": coords.tolist()},
            }
        )
    doc = {
        "type": "FeatureCollection",
        "crs": {"type": "name", "properties": {"name": "EPSG:2193"}},
        "features": features,
    }
    path = folder / "maunga-whau.geojson"
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize("orientation", ["uphill", "upright"])
def test_a_real_contour_file_s_labels_face_uphill(tmp_path: Path, orientation: str) -> None:
    source = maunga_whau_contours_file(tmp_path, seed=3)
    store = CCSStore(tmp_path / "s.sqlite")
    options = CartographyOptions(index_every=2, label_orientation=orientation)
    build_dataset(
        store,
        SourceSpec(source, "mw", "mw", source_scale=5_000.0, target_scale=50_000.0, cartography=options),
        workers=1,
    )
    stored = store.labels("mw")
    assert stored is not None
    a = stored.anchors
    assert len(a.xy) >= 10
    grid = read_dem(MAUNGA_WHAU_ASC)
    inverse = ~rasterio.Affine(*grid.transform)

    def dem(points: np.ndarray) -> np.ndarray:
        x, y = TO_2193.transform(points[:, 0], points[:, 1])
        col, row = inverse * (np.asarray(x), np.asarray(y))
        return ndimage.map_coordinates(
            grid.z.filled(np.nan), [np.asarray(row) - 0.5, np.asarray(col) - 0.5], order=1, mode="nearest"
        )

    step = text_top(a.angle) * 2.0  # 2 m of Web Mercator each side (the DEM's cells are 10 m)
    diff = dem(a.xy + step) - dem(a.xy - step)
    told = np.isfinite(diff) & (np.abs(diff) > 0.05)
    if orientation == "upright":
        assert (np.abs(a.angle) <= 90.0).all()
        assert (diff[told] < 0).sum() >= 3  # upright labels: some tops face downhill
        return
    # Every top faces uphill, but where that would turn the text past the limit (then it is upright).
    wrong = told & (diff < 0)
    assert (np.abs(a.angle[wrong]) <= 180.0 - UPSIDE_DOWN_LIMIT_DEG + 1e-6).all(), a.angle[wrong]
    assert (diff[told] > 0).mean() >= 0.6
    assert (np.abs(a.angle) > 90.0).sum() >= 3  # some read past upright: turned by their neighbours
