import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from reference_tiles import clip_lines, clip_to_grid, row_runs

from engine.errors import InvalidParameter, TileOutOfRange
from engine.serve.pack import LineSet
from engine.tiles.clip import clip_lines_fast
from engine.tiles.grid import (
    HALF_WORLD_M,
    Tile,
    check_fractional_zoom,
    check_tile,
    lonlat_to_mercator,
    mercator_to_lonlat,
    quantize,
    tile_bounds,
    tile_center_latitude,
    tiles_covering,
)
from engine.tiles.runs import RunSet, chunk_bounds, chunk_bounds_packed, collinear_free, ranges, slice_runs
from engine.types import Bounds


def test_tile_bounds_world():
    assert tile_bounds(Tile(0, 0, 0)) == Bounds(-HALF_WORLD_M, -HALF_WORLD_M, HALF_WORLD_M, HALF_WORLD_M)


@given(st.integers(0, 20), st.floats(0, 1, exclude_max=True), st.floats(0, 1, exclude_max=True))
def test_tiles_covering_point_contains_it(z, fx, fy):
    x = -HALF_WORLD_M + fx * 2 * HALF_WORLD_M
    y = -HALF_WORLD_M + fy * 2 * HALF_WORLD_M
    (t,) = tiles_covering(Bounds(x, y, x, y), z)
    b = tile_bounds(t)
    assert b.minx - 1e-6 <= x <= b.maxx + 1e-6 and b.miny - 1e-6 <= y <= b.maxy + 1e-6


@pytest.mark.parametrize(("z", "x", "y"), [(-1, 0, 0), (17, 0, 0), (2, 4, 0), (2, 0, 4), (2, -1, 0)])
def test_check_tile_rejects(z, x, y):
    with pytest.raises(TileOutOfRange):
        check_tile(z, x, y, 0, 16)


@pytest.mark.parametrize("zoom", [4.99, 6.0, float("nan"), float("inf")])
def test_fractional_zoom_rejects(zoom):
    with pytest.raises(InvalidParameter):
        check_fractional_zoom(5, zoom)


def test_fractional_zoom_default():
    assert check_fractional_zoom(5, None) == 5.0 and check_fractional_zoom(5, 5.5) == 5.5


def test_center_latitude():
    assert tile_center_latitude(Tile(0, 0, 0)) == pytest.approx(0.0)
    assert tile_center_latitude(Tile(1, 0, 0)) > 0


@given(st.floats(-179, 179), st.floats(-85, 85))
def test_mercator_round_trip(lon, lat):
    x, y = lonlat_to_mercator(np.array([lon]), np.array([lat]))
    lo, la = mercator_to_lonlat(x, y)
    assert lo[0] == pytest.approx(lon, abs=1e-9) and la[0] == pytest.approx(lat, abs=1e-9)


def test_quantize_y_down():
    b = Bounds(0.0, 0.0, 100.0, 100.0)
    q = quantize(np.array([[0.0, 100.0], [100.0, 0.0], [50.0, 50.0]]), b, 4096)
    assert q.tolist() == [[0, 0], [4096, 4096], [2048, 2048]]


def test_clip_to_grid():
    line = np.array([[-500, 100], [5000, 100]])
    (part,) = clip_to_grid(line, -64, 4160)
    assert part.tolist() == [[-64, 100], [4160, 100]]
    assert clip_to_grid(np.array([[5000, 5000], [6000, 6000]]), -64, 4160) == []


def test_row_runs_cover_the_box():
    rng = np.random.default_rng(0)
    rows = np.cumsum(rng.normal(size=(500, 2)), axis=0)
    cb = chunk_bounds([rows])
    box = Bounds(-5, -5, 5, 5)
    runs = row_runs(cb, box, len(rows))
    covered = np.zeros(len(rows), bool)
    for a, b in runs:
        covered[a:b] = True
    inside = (np.abs(rows) <= 5).all(axis=1)
    assert covered[inside].all()


def test_collinear_free():
    rows = np.array([[0.0, 0], [1, 0], [2, 0], [2, 1], [2, 2]])
    assert collinear_free(rows).tolist() == [0, 2, 4]
    assert math.isclose(len(collinear_free(rows[:2])), 2)


def test_chunk_bounds_packed_matches_per_line():
    rng = np.random.default_rng(1)
    lines = [np.cumsum(rng.normal(size=(m, 2)), axis=0) for m in (1, 2, 33, 64, 65, 200)]
    tops = [v + 3 for v in lines]
    off = np.concatenate([[0], np.cumsum([len(v) for v in lines])])
    boxes, chunk_off = chunk_bounds_packed([np.concatenate(lines), np.concatenate(tops)], off)
    for i, (b, t) in enumerate(zip(lines, tops, strict=True)):
        assert np.array_equal(boxes[chunk_off[i] : chunk_off[i + 1]], chunk_bounds([b, t]))


def test_chunk_bounds_packed_boxes_of_chunks_with_nan_rows_are_nan_on_that_axis():
    """Filler rows (NaN) between a tile's stored pieces must leave their chunks' boxes meeting nothing."""
    rng = np.random.default_rng(2)
    lines = [np.cumsum(rng.normal(size=(m, 2)), axis=0) for m in (2, 40, 97, 130)]
    lines[1][5, 0] = np.nan  # one axis only
    lines[2][40:71] = np.nan  # a whole chunk of filler, and the first row of the next
    lines[3][-1, 1] = np.nan  # a line's last row, shared by no next chunk
    tops = [v + 3 for v in lines]
    off = np.concatenate([[0], np.cumsum([len(v) for v in lines])])
    boxes, chunk_off = chunk_bounds_packed([np.concatenate(lines), np.concatenate(tops)], off)
    for i, (b, t) in enumerate(zip(lines, tops, strict=True)):
        assert np.array_equal(boxes[chunk_off[i] : chunk_off[i + 1]], chunk_bounds([b, t]), equal_nan=True)
    assert np.isnan(boxes).any(axis=1).sum() == 1 + 2 + 1


def test_ranges():
    assert ranges(np.array([0, 5, 7]), np.array([2, 5, 9])).tolist() == [0, 1, 7, 8]
    assert ranges(np.array([], dtype=np.int64), np.array([], dtype=np.int64)).tolist() == []


def test_slice_runs_matches_numpy():
    rng = np.random.default_rng(2)
    base = np.cumsum(rng.normal(size=(300, 2)) * 50, axis=0)
    top = base + rng.normal(size=(300, 2)) * 20
    sig = np.abs(rng.normal(size=(300, 2))).astype(np.float32) * 30
    bounds = Bounds(-2000.0, -2000.0, 2000.0, 2000.0)
    a, b = np.array([0, 100, 250]), np.array([90, 240, 300])
    run_t = np.array([0.0, 0.4, 1.0])
    col = np.array([0, 0, 1])
    q, plen, box = slice_runs(
        RunSet(a, b, col, np.zeros(3, bool)), run_t, LineSet.of(base, top, [300], sig), 10.0, bounds, 4096
    )
    pieces = np.split(q, np.cumsum(plen)[:-1])
    for r in range(3):
        rows = np.arange(a[r], b[r])
        keep = sig[rows, col[r]] > 10.0
        keep[[0, -1]] = True
        rows = rows[keep]
        xy = base[rows] + run_t[r] * (top[rows] - base[rows]) if 0 < run_t[r] < 1 else (top if run_t[r] else base)[rows]
        ref = quantize(xy, bounds, 4096)
        ref = ref[np.concatenate([[True], np.any(ref[1:] != ref[:-1], axis=1)])]
        assert np.array_equal(pieces[r], ref)
        assert box[r].tolist() == [*ref.min(axis=0), *ref.max(axis=0)]


#: Grid units by which two clips of one line may differ (per input line, Hausdorff distance): each side rounds
#: its cut points to the grid, and a cut point whose exact coordinate is a rounding tie (x.5) may round either
#: way in the two float computations; a piece shorter than that may then collapse to a point on one side only.
CLIP_TOLERANCE = 1.0


def pieces_of(clipped: tuple[np.ndarray, np.ndarray, np.ndarray], line: int) -> list[np.ndarray]:
    """The pieces a clip made of input line ``line``."""
    pts, lens, src = clipped
    if len(lens) == 0:  # np.split would give one empty piece
        return []
    return [p for p, s in zip(np.split(pts, np.cumsum(lens)[:-1]), src, strict=True) if s == line]


def test_clip_lines_fast_agrees_with_shapely():
    """Every line of every case: pieces on one side exactly when on the other, within CLIP_TOLERANCE of them."""
    import shapely

    rng = np.random.default_rng(3)
    for case in range(500):
        lens = rng.integers(2, 10, size=rng.integers(1, 4))
        q = rng.integers(-40, 41, size=(int(lens.sum()), 2))
        theirs = clip_lines(q, lens, -10, 20)
        ours = clip_lines_fast(q, lens, -10, 20)
        assert len(ours[0]) == int(ours[1].sum()) and (ours[1] >= 2).all()
        assert ((ours[0] >= -10) & (ours[0] <= 20)).all()
        for line in range(len(lens)):
            a, b = pieces_of(theirs, line), pieces_of(ours, line)
            assert bool(a) == bool(b), f"case {case} line {line}: shapely {len(a)} pieces, clip_lines_fast {len(b)}"
            if a:
                apart = shapely.hausdorff_distance(shapely.MultiLineString(a), shapely.MultiLineString(b))
                assert apart <= CLIP_TOLERANCE, f"case {case} line {line}: {apart:.3f} grid units apart"
