"""The sea and the sea floor, and labels that read uphill (issue 25 items 3 and 4; docs/design.md section 9).

Real components throughout: DEMs written as GeoTIFFs, read and traced by the engine, built into a store, its
labels placed and its tiles rendered. The sea floor is matplotlib's topobathy.npz (tests/real_dems.py).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pyproj
import pytest
import rasterio
from hypothesis import given, settings
from hypothesis import strategies as st
from real_dems import topobathy
from scipy import ndimage
from support.mvt import decode_served

from engine.build.datasets import SourceSpec, build_dataset
from engine.build.labels import label_last_zoom
from engine.cartography.dataset import MINUS, dataset_cartography, label_sources
from engine.cartography.labels import UPSIDE_DOWN_LIMIT_DEG, orient_angle, place_labels
from engine.cartography.options import CartographyOptions
from engine.intervals import infer_interval
from engine.io.dem import contours_from_dem
from engine.io.dem_tracing import LEVEL_OFFSET, iter_levels, uphill_side
from engine.serve.renderer import Renderer
from engine.store.store import CCSStore
from engine.tiles.grid import tiles_covering
from engine.types import Bounds

#: Rows and columns of topobathy.npz used: the Strait of Georgia and the Coast Mountains (sea floor to summits).
WINDOW = (slice(40, 91), slice(50, 110))
INTERVAL = 100.0
TO_LONLAT = pyproj.Transformer.from_crs("EPSG:3857", "EPSG:4326", always_xy=True)


def write_topobathy(path: Path, *, north_up: bool) -> Path:
    """The window of topobathy.npz as a lon/lat GeoTIFF, row 0 north (``north_up``) or south as in the file."""
    z, lon, lat = topobathy()
    z, lon, lat = z[WINDOW], lon[WINDOW[1]], lat[WINDOW[0]]
    dlon, dlat = float(np.mean(np.diff(lon))), float(np.mean(np.diff(lat)))  # rows run north, evenly enough
    west, south = float(lon[0]) - dlon / 2, float(lat[0]) - dlat / 2
    if north_up:
        z = z[::-1]
        transform = rasterio.Affine(dlon, 0.0, west, 0.0, -dlat, south + dlat * z.shape[0])
    else:
        transform = rasterio.Affine(dlon, 0.0, west, 0.0, dlat, south)
    profile = {"driver": "GTiff", "height": z.shape[0], "width": z.shape[1], "count": 1, "dtype": "float32"}
    with rasterio.open(path, "w", **profile, transform=transform, crs="EPSG:4326") as dst:
        dst.write(z.astype("float32"), 1)
    return path


def dem_at(path: Path, xy_3857: np.ndarray) -> np.ndarray:
    """Bilinear heights of the GeoTIFF at EPSG:3857 points."""
    with rasterio.open(path) as src:
        z = src.read(1).astype(np.float64)
        inverse = ~src.transform
    lon, lat = TO_LONLAT.transform(xy_3857[:, 0], xy_3857[:, 1])
    col, row = inverse * (np.asarray(lon), np.asarray(lat))
    return ndimage.map_coordinates(z, [np.asarray(row) - 0.5, np.asarray(col) - 0.5], order=1, mode="nearest")


def up_normal(angle_deg: np.ndarray) -> np.ndarray:
    """(n, 2) unit vector toward the top of text rotated ``angle_deg`` clockwise (x east, y north)."""
    a = np.radians(angle_deg)
    return np.column_stack([np.sin(a), np.cos(a)])


#: Metres from a label's anchor the DEM is sampled toward its top and its foot (a few metres: on a grid of
#: 2.4 km cells the ground a few hundred metres off a line can already turn, by a ridge or a valley beside it).
STEP_M = 5.0
#: Height difference over 2 x STEP_M below which the DEM does not tell the sides apart: there, bilinear heights
#: and the tracer's heights linear along cell edges can disagree on which side is higher (under 1 % of labels).
FLAT_M = 0.1


def top_minus_foot(path: Path, xy: np.ndarray, angle: np.ndarray, step_m: float = STEP_M) -> np.ndarray:
    """The DEM ``step_m`` toward each label's top minus as far toward its foot."""
    n = up_normal(angle) * step_m
    return dem_at(path, xy + n) - dem_at(path, xy - n)


def built(folder: Path, name: str, *, north_up: bool, options: CartographyOptions) -> tuple[Path, CCSStore]:
    dem = write_topobathy(folder / f"{name}.tif", north_up=north_up)
    store = CCSStore(folder / f"{name}.sqlite")
    spec = SourceSpec(dem, name, name, interval=INTERVAL, source_scale=50_000.0, target_scale=500_000.0,
                      cartography=options)
    build_dataset(store, spec, workers=1)
    return dem, store


@pytest.fixture(scope="module")
def coast(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, CCSStore]:
    """Row 0 south (uphill on the traced lines' left), the 0 m line as coastline, depths as negatives; index
    contours every 200 m, so that depths down to the window's -427 m are labelled."""
    return built(tmp_path_factory.mktemp("coast"), "coast", north_up=False,
                 options=CartographyOptions(index_every=2, sea="coastline"))


@pytest.fixture(scope="module")
def dropped(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, CCSStore]:
    """Row 0 north (uphill on the traced lines' right), the 0 m line dropped, depths below the datum."""
    return built(tmp_path_factory.mktemp("drop"), "drop", north_up=True,
                 options=CartographyOptions(index_every=2, sea="drop", depth_labels="below-datum"))


def tile_features(store: CCSStore, dataset: str, z: int) -> list[dict]:
    renderer = Renderer(store)
    info = store.dataset(dataset)
    out: list[dict] = []
    for tile in tiles_covering(Bounds(*info.bounds_3857), z):
        out += decode_served(renderer.tile(dataset, *tile).data).get("contours", {}).get("features", [])
    return out


@pytest.mark.parametrize("which", ["coast", "dropped"])
def test_labels_face_uphill_on_the_sea_floor_and_the_mountains(which: str, request: pytest.FixtureRequest) -> None:
    dem, store = request.getfixturevalue(which)
    labels = store.labels(which if which == "coast" else "drop")
    assert labels is not None
    anchors = labels.anchors
    assert len(anchors) >= 20 and (anchors.elevation < 0).sum() >= 3  # heights and depths both labelled
    diff = top_minus_foot(dem, anchors.xy, anchors.angle)
    told = np.abs(diff) > FLAT_M
    assert told.mean() > 0.95
    # A label is turned upright (top downhill) only where its top toward higher ground would be more than
    # UPSIDE_DOWN_LIMIT_DEG from upright: an upright label within 180 - limit of level.
    turned = told & (diff < 0)
    assert (np.abs(anchors.angle[turned]) <= 180.0 - UPSIDE_DOWN_LIMIT_DEG + 1e-6).all(), anchors.angle[turned]
    assert (diff[told] > 0).mean() >= 0.6
    assert (np.abs(anchors.angle) > 90.0).sum() >= 3  # some read past upright: not the upright rule by chance


def test_the_upright_option_keeps_todays_labels(coast: tuple[Path, CCSStore]) -> None:
    dem, store = coast
    info = store.dataset("coast")
    elevations = store.elevations("coast")
    carto = dataset_cartography(info, info.interval or infer_interval(elevations), elevations)
    upright = replace(carto, options=replace(carto.options, label_orientation="upright"))
    sources = label_sources(upright, store.load(store.all_fids("coast")))
    anchors = place_labels(sources, info.ladder, carto.latitude, label_last_zoom(16))
    stored = store.labels("coast")
    assert stored is not None
    assert (np.abs(anchors.angle) <= 90.0).all()
    # The same places; each angle the stored (uphill) one, or that turned half a turn.
    np.testing.assert_allclose(anchors.xy, stored.anchors.xy)
    turn = (stored.anchors.angle - anchors.angle) % 360.0
    assert np.all(np.isclose(turn, 0.0, atol=1e-6) | np.isclose(turn, 180.0, atol=1e-6) | np.isclose(turn, 360.0))
    diff = top_minus_foot(dem, anchors.xy, anchors.angle)
    turned = (diff < -FLAT_M) & (np.abs(anchors.angle) > 180.0 - UPSIDE_DOWN_LIMIT_DEG)
    assert turned.sum() >= 3  # upright: some tops face downhill where uphill labels would not


def test_depths_are_labelled_with_a_minus_or_below_the_datum(coast, dropped) -> None:
    for store, dataset, sign in ((coast[1], "coast", MINUS), (dropped[1], "drop", "")):
        stored = store.labels(dataset)
        assert stored is not None
        a = stored.anchors
        for text, elevation in zip(a.text, a.elevation.tolist(), strict=True):
            if elevation < 0:
                assert text == f"{sign}{-elevation:g} m"
            else:
                assert text == f"{elevation:g} m"
        assert 0.0 not in a.elevation.tolist()  # neither a coastline nor a dropped line carries a height label


def test_the_zero_line_is_a_coastline_or_left_out(coast, dropped) -> None:
    for z in (9, 11):
        features = tile_features(coast[1], "coast", z)
        zero = [f for f in features if f["properties"]["elevation"] == 0]
        assert zero and all(f["properties"]["coastline"] is True for f in zero)
        assert all(f["properties"]["hide_zoom"] == -1 for f in zero)  # of the top rank: it never fades
        assert not any(f["properties"]["coastline"] for f in features if f["properties"]["elevation"] != 0)
        others = tile_features(dropped[1], "drop", z)
        assert others and not [f for f in others if f["properties"]["elevation"] == 0]
        assert all("coastline" not in f["properties"] for f in others)


def test_kept_zero_line_is_an_ordinary_contour(coast) -> None:
    store = coast[1]
    info = store.dataset("coast")
    elevations = store.elevations("coast")
    carto = dataset_cartography(info, info.interval or infer_interval(elevations), elevations)
    keep = replace(carto, options=replace(carto.options, sea="keep"))
    levels = np.array([0.0, 100.0, -100.0])
    assert keep.shown_in_tile(levels, 20).all() and "coastline" not in keep.line_columns(levels)
    sources = label_sources(keep, store.load(store.all_fids("coast")))
    assert any(s.elevation == 0 and s.text == "0 m" for s in sources)


# -- no line along nodata or sea-mask edges ---------------------------------------------------------------


def holed_plane(n: int = 80) -> tuple[np.ndarray, np.ndarray]:
    """A tilted plane (heights linear in row and column), and its mask of nodata: a border three cells wide
    and a hole in the middle (a lake or a sea mask given as nodata)."""
    row, col = np.mgrid[0:n, 0:n].astype(np.float64)
    z = 3.0 * col + 1.7 * row
    mask = np.zeros_like(z, dtype=bool)
    mask[:3], mask[-3:], mask[:, :3], mask[:, -3:] = True, True, True, True
    mask[30:50, 25:55] = True
    return z, mask


@pytest.mark.parametrize("block", [None, 32])
def test_no_line_runs_along_a_nodata_edge(tmp_path: Path, block: int | None) -> None:
    z, mask = holed_plane()
    data = np.where(mask, -9999.0, z).astype("float32")
    path = tmp_path / "holed.tif"
    profile = {"driver": "GTiff", "height": z.shape[0], "width": z.shape[1], "count": 1, "dtype": "float32",
               "nodata": -9999.0}
    transform = rasterio.Affine(10.0, 0.0, 500_000.0, 0.0, -10.0, 5_000_000.0)
    with rasterio.open(path, "w", **profile, transform=transform, crs="EPSG:32633") as dst:
        dst.write(data, 1)
    contours = contours_from_dem(path, interval=20.0, block=block)
    assert contours.working_crs.endswith("32633") and len(contours.contours) > 10
    for c in contours.contours:
        xy = np.asarray(c.coords)
        col, row = (xy[:, 0] - 500_000.0) / 10.0 - 0.5, (5_000_000.0 - xy[:, 1]) / 10.0 - 0.5
        # Every vertex lies where the plane is at the line's level: a line along a nodata edge would not.
        np.testing.assert_allclose(3.0 * col + 1.7 * row, c.elevation + LEVEL_OFFSET, atol=1e-3)
        # and no vertex lies inside the nodata (on its edge cells at most).
        inside = ndimage.binary_erosion(mask, iterations=1)
        r, k = np.floor(row + 0.5).astype(int), np.floor(col + 0.5).astype(int)
        assert not inside[np.clip(r, 0, 79), np.clip(k, 0, 79)].any()


# -- the uphill rule on random cones and slopes -----------------------------------------------------------


@settings(max_examples=60, deadline=None)
@given(
    kind=st.sampled_from(["cone", "pit", "slope"]),
    cx=st.floats(10, 30),
    cy=st.floats(10, 30),
    gx=st.floats(-3, 3),
    gy=st.floats(-3, 3),
    north_up=st.booleans(),
    rotation=st.floats(-60, 60),
)
def test_the_text_top_faces_uphill_on_random_cones_and_slopes(kind, cx, cy, gx, gy, north_up, rotation) -> None:
    row, col = np.mgrid[0:41, 0:41].astype(np.float64)

    def height(c: np.ndarray, r: np.ndarray) -> np.ndarray:
        if kind == "slope":
            return gx * c + gy * r
        d = np.hypot(c - cx, r - cy)
        return 100.0 - 4.0 * d if kind == "cone" else 4.0 * d

    z = np.ma.masked_invalid(height(col, row))
    if np.ptp(z) < 5.0:
        return
    # A geotransform: cells of 10 m, rotated, rows running south (north-up) or north.
    th = np.radians(rotation)
    sy = -1.0 if north_up else 1.0
    a, b, d, e = 10 * np.cos(th), -10 * sy * np.sin(th), 10 * np.sin(th), 10 * sy * np.cos(th)
    transform = (a, b, 0.0, d, e, 0.0)
    side = 1 if uphill_side(transform) == "left" else -1
    inverse = np.linalg.inv(np.array([[a, b], [d, e]]))
    levels = np.arange(np.ceil(z.min() / 5.0) * 5.0, z.max(), 5.0)
    checked = 0
    for _, lines in iter_levels(z, levels):
        for line in lines:
            if len(line) < 3:
                continue
            xy = line @ np.array([[a, d], [b, e]])  # grid index space to the CRS (the offset does not matter)
            k = len(line) // 2
            dx, dy = xy[k + 1] - xy[k - 1]
            angle = orient_angle(np.array([dx]), np.array([dy]), side)
            n = up_normal(angle)[0] * 2.0  # 2 m to the text's top and foot
            ends = np.array([xy[k] + n, xy[k] - n]) @ inverse.T
            hi, lo = height(ends[:, 0], ends[:, 1])
            if abs(angle[0]) <= 180.0 - UPSIDE_DOWN_LIMIT_DEG and not hi > lo:
                continue  # turned upright: allowed only near level
            assert hi > lo, (kind, angle, hi, lo)
            checked += 1
    assert checked > 0 or kind == "slope"


# -- the options ------------------------------------------------------------------------------------------


def test_the_options_are_checked_stored_and_leave_older_hashes_alone() -> None:
    from engine.cartography.schedule import check_units
    from engine.errors import InvalidParameter

    given = CartographyOptions("fathoms", 5, "ccsm", None, None, "Coastline", "below-datum", "upright").checked()
    assert (given.units, given.sea, given.label_orientation) == ("fm", "coastline", "upright")
    assert CartographyOptions.from_params({"cartography": given.as_params()}) == given
    assert set(CartographyOptions(units="m").as_params()) == {
        "units", "index_every", "attribute_names", "schedule", "attribution"
    }
    assert check_units("fm") == "fm"
    for bad in ({"sea": "ocean"}, {"depth_labels": "up"}, {"label_orientation": "sideways"}):
        with pytest.raises(InvalidParameter, match=next(iter(bad))):
            CartographyOptions(**bad).checked()
