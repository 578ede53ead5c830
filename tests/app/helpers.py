"""Shared checks of the service tests."""

from __future__ import annotations

import math

from support.mvt import decode

EXTENT = 4096
BUFFER = 64


def lines_of(geometry: dict) -> list[list[list[int]]]:
    if geometry["type"] == "LineString":
        return [geometry["coordinates"]]
    assert geometry["type"] == "MultiLineString", geometry["type"]
    return geometry["coordinates"]


def check_tile(data: bytes) -> list[dict]:
    """Decode an MVT and check the contract: layer, properties, ids, coordinates within the buffer."""
    tile = decode(data)
    assert list(tile) in (["contours"], ["contours", "contour_labels"])
    layer = tile["contours"]
    assert layer["extent"] == EXTENT
    ids = set()
    for f in layer["features"]:
        assert set(f["properties"]) == {"elevation", "index", "t", "level", "rank", "fade_zoom", "hide_zoom"}
        assert isinstance(f["properties"]["index"], bool)
        assert 0.0 <= f["properties"]["t"] <= 1.0
        assert isinstance(f["id"], int) and f["id"] not in ids
        ids.add(f["id"])
        for line in lines_of(f["geometry"]):
            assert len(line) >= 2
            for x, y in line:
                assert -BUFFER <= x <= EXTENT + BUFFER and -BUFFER <= y <= EXTENT + BUFFER
    return layer["features"]


def tile_for(lon: float, lat: float, z: int) -> tuple[int, int, int]:
    n = 2**z
    x = int((lon + 180) / 360 * n)
    y = int((1 - math.asinh(math.tan(math.radians(lat))) / math.pi) / 2 * n)
    return z, x, y


def grid_to_lonlat(z: int, x: int, y: int, gx: float, gy: float) -> tuple[float, float]:
    n = 2**z
    lon = (x + gx / EXTENT) / n * 360 - 180
    lat = math.degrees(math.atan(math.sinh(math.pi * (1 - 2 * (y + gy / EXTENT) / n))))
    return lon, lat
