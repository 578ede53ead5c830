"""Hillshade raster tiles of a dataset's DEM, to lie under the contours."""

from __future__ import annotations

from fastapi import APIRouter, Request, Response

from app.http.disconnect import unless_client_goes
from app.http.responses import etag_matches, make_etag
from app.render.jobs import HillshadeJob
from app.routes.params import DatasetPath, LanesDep, ServiceDep, SettingsDep, TileX, TileY, TileZ, tile_responses
from engine.tiles.grid import check_tile

router = APIRouter(tags=["tiles"])


@router.get(
    "/hillshade/{dataset}/{z}/{x}/{y}.png",
    response_class=Response,
    responses=tile_responses(
        {"content": {"image/png": {}}, "description": "A 256 px grey hillshade tile (alpha 0 off the DEM)."},
        "The tile misses the DEM.",
        "Unknown dataset, a dataset without a DEM, or z/x/y outside the tile matrix.",
    ),
    name="get_hillshade_tile",
)
async def get_hillshade_tile(
    request: Request,
    dataset: DatasetPath,
    z: TileZ,
    x: TileX,
    y: TileY,
    service: ServiceDep,
    settings: SettingsDep,
    lanes: LanesDep,
) -> Response:
    """One hillshade tile of the DEM a dataset was made from (or was given with)."""
    tile = check_tile(z, x, y, settings.min_zoom, settings.max_zoom)
    version = service.require_ready(dataset)
    etag = make_etag("hillshade", dataset, version, z, x, y)
    headers = {"ETag": etag, "Cache-Control": f"public, max-age={settings.cache_max_age}"}
    if etag_matches(request, etag):
        return Response(status_code=304, headers=headers)
    # Shading is CPU work (the relief once per worker, then each tile): it runs in the heavy render lane.
    job = HillshadeJob(dataset, tile.z, tile.x, tile.y, store=service.settings.store_path)
    png = (await unless_client_goes(request, lanes.heavy.run(job))).body
    if png is None:
        return Response(status_code=204, headers=headers)
    return Response(png, media_type="image/png", headers=headers)
