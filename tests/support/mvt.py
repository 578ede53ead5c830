"""Decoding Mapbox Vector Tiles in the tests (mapbox_vector_tile, y down as the tiles are written)."""

from __future__ import annotations

from typing import Any

import mapbox_vector_tile


def decode(data: bytes) -> dict[str, Any]:
    """The tile's layers by name, with y pointing down (the MVT grid as written, not flipped)."""
    return mapbox_vector_tile.decode(data, default_options={"y_coord_down": True})


def decode_served(data: bytes | None) -> dict[str, Any]:
    """:func:`decode` of what the renderer served, where None means it had nothing to draw (no layers)."""
    return {} if data is None else decode(data)
