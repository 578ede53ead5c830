"""Vector tiles and TileJSON."""

from __future__ import annotations

from html import escape
from typing import Annotated, Any
from urllib.parse import urlencode

from fastapi import APIRouter, Depends, Path, Request, Response
from fastapi.responses import JSONResponse

from app.http.disconnect import unless_client_goes
from app.http.public_url import public_base_url
from app.http.responses import accepts_gzip, body_response, etag_matches, make_etag
from app.render.jobs import MorphJob, Rendered, TileJob
from app.routes.dependencies import TileQuery
from app.routes.params import DatasetPath, LanesDep, ServiceDep, SettingsDep, TileX, TileY, TileZ, tile_responses
from app.service import DatasetService, lonlat_bounds
from app.settings import Settings
from engine.cartography.dataset import contour_fields, label_fields
from engine.serve.label_layer import LABEL_LAYER
from engine.serve.morph_tiles import MORPH_END_LAYER, MORPH_START_LAYER, MORPH_T_SAMPLES
from engine.tiles.grid import check_tile
from engine.tiles.scale import zoom_for_scale

router = APIRouter(tags=["tiles"])

MVT_MEDIA_TYPE = "application/vnd.mapbox-vector-tile"
#: The 404 of the vector and morph tiles.
OUTSIDE_SERVED_TILES = "Unknown dataset, or z/x/y outside the tile matrix or the served zooms."

#: The morph tile's extra fields, as TileJSON lists them (docs/morph-tiles.md).
MORPH_FIELDS = {
    **{f"t{k}": f"Number: t at zoom z + {k}/{MORPH_T_SAMPLES}" for k in range(1, MORPH_T_SAMPLES + 1)},
    "min_zoom": "Number: draw the contour only where the zoom is above this",
}
#: What a morph client needs to know about the format.
MORPH_TILEJSON = {
    "version": 1,
    "t_samples": MORPH_T_SAMPLES,
    "start_layer": MORPH_START_LAYER,
    "end_layer": MORPH_END_LAYER,
}

@router.get(
    "/tiles/{dataset}/{z}/{x}/{y}.mvt",
    response_class=Response,
    responses=tile_responses(
        {"content": {MVT_MEDIA_TYPE: {}}, "description": "The tile (one layer `contours`)."},
        "No contour in this tile.",
        OUTSIDE_SERVED_TILES,
    ),
    name="get_tile",
)
async def get_tile(
    request: Request,
    dataset: DatasetPath,
    z: TileZ,
    x: TileX,
    y: TileY,
    q: Annotated[TileQuery, Depends()],
    service: ServiceDep,
    settings: SettingsDep,
    lanes: LanesDep,
) -> Response:
    """One Mapbox Vector Tile of a dataset's contours, generalized for the tile's (fractional) zoom."""
    renderer = service.renderer
    _, zoom, t = renderer.check_tile_request(z, x, y, q.zoom, q.method, q.t)
    method = renderer.methods[q.method]
    version = service.require_ready(dataset)
    gz = accepts_gzip(request)
    etag = make_etag(
        dataset,
        version,
        z,
        x,
        y,
        zoom,
        q.method,
        t if method.honours_t else None,
        settings.tile_extent,
        settings.tile_buffer,
        "gz" if gz else "id",
    )
    headers = {"ETag": etag, "Cache-Control": f"public, max-age={settings.cache_max_age}"}
    if etag_matches(request, etag):
        return Response(status_code=304, headers=headers)
    job = TileJob(dataset, z, x, y, zoom, q.method, t, store=service.settings.store_path, gzip=gz)
    result = await unless_client_goes(request, lanes.for_tile(method).run(job))
    headers["X-Tile-Scale"] = f"{result.scale:.1f}"
    headers["Server-Timing"] = server_timing(result)
    if result.body is None:
        return Response(status_code=204, headers=headers)
    return body_response(request, result.body, MVT_MEDIA_TYPE, headers, gzipped=result.gzipped)


@router.get(
    "/morph/{dataset}/{z}/{x}/{y}.mvt",
    response_class=Response,
    responses=tile_responses(
        {
            "content": {MVT_MEDIA_TYPE: {}},
            "description": "The morph tile: layers `contours` (at zoom z) and `contours_end` (at z + 1).",
        },
        "No contour in this tile.",
        OUTSIDE_SERVED_TILES,
    ),
    name="get_morph_tile",
)
async def get_morph_tile(
    request: Request,
    dataset: DatasetPath,
    z: Annotated[int, Path(description="Zoom level of the tile; it carries the morph over [z, z + 1).", ge=0, le=30)],
    x: TileX,
    y: TileY,
    service: ServiceDep,
    settings: SettingsDep,
    lanes: LanesDep,
) -> Response:
    """One morph tile: the CCSM contours at both ends of the zoom level with the same vertices, and their t
    through the level, so a client draws every zoom inside the level without asking again
    (docs/morph-tiles.md)."""
    check_tile(z, x, y, settings.min_zoom, settings.max_zoom)
    version = service.require_ready(dataset)
    gz = accepts_gzip(request)
    etag = make_etag("morph", dataset, version, z, x, y, settings.tile_extent, settings.tile_buffer, gz)
    headers = {"ETag": etag, "Cache-Control": f"public, max-age={settings.cache_max_age}"}
    if etag_matches(request, etag):
        return Response(status_code=304, headers=headers)
    job = MorphJob(dataset, z, x, y, store=service.settings.store_path, gzip=gz)
    result = await unless_client_goes(request, lanes.morph.run(job))
    headers["Server-Timing"] = server_timing(result)
    if result.body is None:
        return Response(status_code=204, headers=headers)
    return body_response(request, result.body, MVT_MEDIA_TYPE, headers, gzipped=result.gzipped)


def server_timing(result: Rendered) -> str:
    """The ``Server-Timing`` header of a drawn tile: milliseconds it waited for a render worker (``queue``)
    and the worker spent drawing it (``render``), so a load test can tell queueing from work."""
    return f"queue;dur={result.wait_s * 1000:.1f}, render;dur={result.work_s * 1000:.1f}"


@router.get("/tiles/{dataset}/tilejson.json", name="get_tilejson")
def get_tilejson(
    request: Request,
    dataset: DatasetPath,
    service: ServiceDep,
    settings: SettingsDep,
) -> Response:
    """TileJSON 3.0.0 of a dataset: tile URL template (keeps this request's query string), bounds, layers."""
    return tilejson_response(request, dataset, "tiles", service, settings)


@router.get("/morph/{dataset}/tilejson.json", name="get_morph_tilejson")
def get_morph_tilejson(
    request: Request,
    dataset: DatasetPath,
    service: ServiceDep,
    settings: SettingsDep,
) -> Response:
    """TileJSON 3.0.0 of a dataset's morph tiles (docs/morph-tiles.md): both layers and ``ccsm_morph``."""
    return tilejson_response(request, dataset, "morph", service, settings)


def tilejson_response(
    request: Request, dataset: str, kind: str, service: DatasetService, settings: Settings
) -> Response:
    """The TileJSON of the per-level tiles (``kind`` tiles) or of the morph tiles (``kind`` morph)."""
    version = service.require_ready(dataset)
    info, interval = service.renderer.info(dataset)
    query = [(k, v) for k, v in request.query_params.multi_items() if k != "v"]
    query.append(("v", str(version)))
    base = public_base_url(request, settings)  # never the Host header: see app/http/public_url.py
    url = f"{base}/{kind}/{dataset}/{{z}}/{{x}}/{{y}}.mvt?{urlencode(query)}"
    bounds = lonlat_bounds(info)
    lat = (bounds[1] + bounds[3]) / 2
    start_zoom = int(
        min(
            settings.max_zoom,
            max(settings.min_zoom, round(float(zoom_for_scale(info.source_scale, lat)) - 1)),
        )
    )
    carto = service.renderer.cartography(dataset)
    fields = {
        **contour_fields(carto),
        "t": "Number: generalization parameter in [0, 1] (0 = source detail)",
    }
    layers: list[dict[str, Any]] = [
        {
            "id": "contours",
            "description": "Contour lines; each feature id is stable across zooms.",
            "minzoom": settings.min_zoom,
            "maxzoom": settings.max_zoom,
            "fields": fields,
        },
        {
            "id": LABEL_LAYER,
            "description": "Label anchors on index contours, fixed per contour (they hold still while lines morph).",
            "minzoom": settings.min_zoom,
            "maxzoom": settings.max_zoom,
            "fields": label_fields(carto),
        },
    ]
    body: dict[str, Any] = {
        "tilejson": "3.0.0",
        "name": info.name,
        "description": "Terrain contours generalized continuously with the zoom (CCSM, Qian et al. 2021).",
        "version": f"1.{version}.0",  # changes with the dataset's data version
        "attribution": escape(carto.options.attribution or f"Contours: ccsm, from {info.source}"),
        "scheme": "xyz",
        "tiles": [url],
        "minzoom": settings.min_zoom,
        "maxzoom": settings.max_zoom,
        "bounds": bounds,
        "center": [round((bounds[0] + bounds[2]) / 2, 6), round(lat, 6), start_zoom],
        "vector_layers": layers,
        "data_version": version,
        "ccsm_cartography": carto.as_json(),
    }
    if kind == "morph":
        fields.update(MORPH_FIELDS)
        layers.insert(
            1,
            {
                "id": MORPH_END_LAYER,
                "description": "The same contours with the same vertices, as at zoom z + 1.",
                "minzoom": settings.min_zoom,
                "maxzoom": settings.max_zoom,
                "fields": {},
            },
        )
        body["ccsm_morph"] = MORPH_TILEJSON
    etag = make_etag("tilejson", dataset, version, url)
    headers = {"ETag": etag, "Cache-Control": f"public, max-age={min(settings.cache_max_age, 60)}"}
    if etag_matches(request, etag):
        return Response(status_code=304, headers=headers)
    return JSONResponse(body, headers=headers)
