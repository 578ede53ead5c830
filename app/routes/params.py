"""The path parameters and answers the per-dataset routes share (vector, morph and hillshade tiles, styles)."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import Depends, Path

from app.render.pool import RenderLanes, get_render_lanes
from app.routes.dependencies import get_service, get_settings
from app.service import DatasetService
from app.settings import Settings

DatasetPath = Annotated[str, Path(description="Dataset id (see GET /datasets).", max_length=64)]
TileZ = Annotated[int, Path(description="Zoom level of the tile.", ge=0, le=30)]
TileX = Annotated[int, Path(description="Tile column, 0 at the antimeridian (west).", ge=0)]
TileY = Annotated[int, Path(description="Tile row, 0 at the north edge (XYZ scheme).", ge=0)]

#: The request's dataset service, settings and render lanes, as route parameters.
ServiceDep = Annotated[DatasetService, Depends(get_service)]
SettingsDep = Annotated[Settings, Depends(get_settings)]
LanesDep = Annotated[RenderLanes, Depends(get_render_lanes)]


def tile_responses(ok: dict[str, Any], no_content: str, not_found: str) -> dict[int | str, dict[str, Any]]:
    """The answers a tile route documents: ``ok`` (200), 204 ``no_content``, 304, 404 ``not_found``, 503."""
    return {
        200: ok,
        204: {"description": no_content},
        304: {"description": "Not modified (If-None-Match matched the ETag)."},
        404: {"description": not_found},
        503: {"description": "Busy, or not drawn within the deadline (request_timeout_s); see Retry-After."},
    }

