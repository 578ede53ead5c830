import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from reference_mvt import encode_tile_reference
from support.mvt import decode

from engine.tiles.grid import drop_repeats
from engine.tiles.mvt import LineFeature, encode_line_tile, encode_tile, varint, varint_array


@given(st.lists(st.integers(0, 2**35 - 1), min_size=1, max_size=50))
def test_varint_array_matches_scalar(values):
    data, starts = varint_array(np.array(values, dtype=np.uint64))
    assert data.tobytes() == b"".join(varint(v) for v in values)
    assert starts[0] == 0


lines = st.lists(st.tuples(st.integers(-64, 4160), st.integers(-64, 4160)), min_size=2, max_size=30)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.lists(lines, min_size=1, max_size=3), min_size=1, max_size=6))
def test_same_tile_as_mapbox_vector_tile(features):
    feats = []
    for i, parts in enumerate(features):
        ps = [drop_repeats(np.array(p, dtype=np.int64)) for p in parts]
        ps = [p for p in ps if len(p) >= 2]
        if ps:
            feats.append(LineFeature(i, ps, {"elevation": float(100 + i), "index": i % 2 == 0, "t": 0.5, "n": -i}))
    if not feats:
        return
    ours = decode(encode_tile({"contours": feats}))
    ref = decode(encode_tile_reference({"contours": feats}))
    assert ours == ref


def test_empty_tile_is_empty_bytes():
    assert encode_tile({"contours": []}) == b""


def test_multilinestring_cursor_carries_between_parts():
    f = LineFeature(3, [np.array([[10, 10], [20, 20]]), np.array([[5, 5], [0, 9]])], {"elevation": 1.0})
    geom = decode(encode_tile({"contours": [f]}))["contours"]["features"][0]["geometry"]
    assert geom == {"type": "MultiLineString", "coordinates": [[[10, 10], [20, 20]], [[5, 5], [0, 9]]]}


@pytest.mark.parametrize("extent", [256, 4096, 8192])
def test_extent(extent):
    f = LineFeature(0, [np.array([[0, 0], [extent, extent]])])
    assert decode(encode_tile({"contours": [f]}, extent))["contours"]["extent"] == extent


@pytest.mark.parametrize(
    "props",
    [
        [{"elevation": 400.0, "index": True, "t": 0.25}, {"elevation": 420.0, "index": False, "t": 0.25}],
        [{"elevation": 400.0, "index": True, "t": 1.0}, {"elevation": 1.0, "index": True, "t": 0.0}],
        [{"elevation": 400, "name": "a"}, {"elevation": 400.0, "name": "b"}],  # not all floats: the dict path
    ],
)
def test_encode_line_tile_same_bytes_as_encode_tile(props):
    parts = [[np.array([[0, 0], [10, 5], [3, 3]])], [np.array([[1, 1], [2, 9]]), np.array([[5, 5], [6, 0]])]]
    features = [LineFeature(7 + i, p, dict(pr)) for i, (p, pr) in enumerate(zip(parts, props, strict=True))]
    pts = np.concatenate([q for p in parts for q in p])
    lens = np.array([len(q) for p in parts for q in p])
    columns = {k: [pr[k] for pr in props] for k in props[0]}
    data = encode_line_tile("contours", [7, 8], columns, pts, lens, np.array([len(p) for p in parts]))
    assert data == encode_tile({"contours": features})
