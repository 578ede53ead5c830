"""The MVT writer the tests compare the compiled encoder with: mapbox_vector_tile through shapely."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from engine.tiles.mvt import DEFAULT_EXTENT, LineFeature


def encode_tile_reference(layers: Mapping[str, Sequence[LineFeature]], extent: int = DEFAULT_EXTENT) -> bytes:
    """The same tile through ``mapbox_vector_tile`` (reference for tests and the benchmark)."""
    import mapbox_vector_tile
    import shapely

    payload = []
    for name, features in layers.items():
        feats = []
        for f in features:
            if not f.parts:
                continue
            geom = (
                shapely.linestrings(f.parts[0])
                if len(f.parts) == 1
                else shapely.multilinestrings([shapely.linestrings(p) for p in f.parts])
            )
            feats.append({"geometry": geom, "properties": dict(f.properties), "id": int(f.id)})
        if feats:
            payload.append({"name": name, "features": feats})
    if not payload:
        return b""
    return bytes(
        mapbox_vector_tile.encode(
            payload, default_options={"extents": extent, "y_coord_down": True, "on_invalid_geometry": None}
        )
    )
