"""Contours at any map scale as GeoJSON."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Query, Request, Response

from app.http.disconnect import unless_client_goes
from app.http.responses import accepts_gzip, body_response, etag_matches, make_etag
from app.render.jobs import SimplifyJob
from app.render.pool import RenderLanes, get_render_lanes
from app.routes.dependencies import MethodName, get_service, get_settings
from app.service import DatasetService
from app.settings import Settings
from engine.checks import MAX_SCALE
from engine.errors import InvalidParameter

router = APIRouter(tags=["simplify"])


def parse_bbox(text: str | None) -> list[float] | None:
    """'west,south,east,north' -> four floats (InvalidParameter when malformed)."""
    if text is None:
        return None
    parts = text.split(",")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise InvalidParameter(f"bbox {text[:100]!r} must be four numbers west,south,east,north") from None
    return values


@router.get(
    "/simplify",
    response_class=Response,
    responses={
        200: {
            "content": {"application/geo+json": {}},
            "description": "GeoJSON FeatureCollection (EPSG:4326).",
        },
        503: {"description": "Busy, or not done within the deadline (request_timeout_s); see Retry-After."},
    },
)
async def simplify(
    request: Request,
    scale: Annotated[
        float,
        Query(
            description="Map scale denominator (250000 for 1:250,000); any positive value.",
            gt=0,
            le=MAX_SCALE,
            allow_inf_nan=False,
        ),
    ],
    service: Annotated[DatasetService, Depends(get_service)],
    settings: Annotated[Settings, Depends(get_settings)],
    lanes: Annotated[RenderLanes, Depends(get_render_lanes)],
    dataset: Annotated[
        str | None, Query(description="Dataset id; default: the first configured dataset.", max_length=64)
    ] = None,
    bbox: Annotated[
        str | None,
        Query(description="Only contours meeting west,south,east,north (degrees).", max_length=200),
    ] = None,
    method: Annotated[MethodName, Query(description="ccsm, dp, wm, vw or original.")] = "ccsm",
    all_levels: Annotated[
        bool,
        Query(description="Keep the levels the interval schedule no longer draws at this scale (counted in "
              "`dropped` otherwise)."),
    ] = False,
) -> Response:
    """Every visible contour at a scale, with elevation, t, similarity and scale per feature."""
    ident = dataset or service.default_dataset()
    box = parse_bbox(bbox)
    version = service.require_ready(ident)
    gz = accepts_gzip(request)
    etag = make_etag("simplify", ident, version, scale, box, method, all_levels, gz)
    headers = {"ETag": etag, "Cache-Control": f"public, max-age={settings.cache_max_age}"}
    if etag_matches(request, etag):
        return Response(status_code=304, headers=headers)
    job = SimplifyJob(ident, scale, box, method, all_levels, store=service.settings.store_path, gzip=gz)
    result = await unless_client_goes(request, lanes.heavy.run(job))
    return body_response(request, result.body or b"", "application/geo+json", headers, gzipped=result.gzipped)
