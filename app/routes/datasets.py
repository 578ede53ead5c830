"""Datasets: list, describe, upload (built in the background), delete."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends, Path, Query, Request, Response
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import JSONResponse

from app.datasets.upload_check import UploadCheck
from app.datasets.uploads import get_upload_checker, receive_upload
from app.http.disconnect import unless_client_goes
from app.routes.dependencies import get_service, get_settings
from app.routes.security import require_json_body, require_writer
from app.service import DatasetService, UploadParams
from app.settings import Settings
from engine.cartography.options import CartographyOptions

router = APIRouter(tags=["datasets"])

NO_STORE = {"Cache-Control": "no-store"}
DatasetPath = Annotated[str, Path(description="Dataset id.", max_length=64)]


@router.get("/datasets")
def list_datasets(service: Annotated[DatasetService, Depends(get_service)]) -> JSONResponse:
    """Every dataset: id, name, state (building, ready or failed)."""
    return JSONResponse(service.summaries(), headers=NO_STORE)


@router.get("/datasets/{dataset}")
def get_dataset(
    dataset: DatasetPath, service: Annotated[DatasetService, Depends(get_service)]
) -> JSONResponse:
    """One dataset: state, extent, counts, scales, build progress and the features left out."""
    return JSONResponse(service.detail(dataset), headers=NO_STORE)


@router.post(
    "/datasets",
    status_code=202,
    dependencies=[Depends(require_writer), Depends(require_json_body)],
    openapi_extra={
        "requestBody": {
            "required": True,
            "description": "A GeoJSON FeatureCollection of contour lines (EPSG:4326) with an elevation property.",
            "content": {
                "application/geo+json": {"schema": {"type": "object"}},
                "application/json": {"schema": {"type": "object"}},
            },
        }
    },
    responses={
        202: {"description": "Accepted; the dataset builds in the background (poll GET /datasets/{id})."},
        400: {"description": "Malformed GeoJSON or no usable contour (the bad features are named)."},
        401: {"description": "CCSM_ADMIN_TOKEN is set and the bearer token is missing or wrong."},
        403: {"description": "No token is set and the client is not local (writes are loopback-only)."},
        409: {"description": "The dataset id exists (ready, building or failed)."},
        413: {"description": "Larger than CCSM_MAX_UPLOAD_MB, or a contour above CCSM_MAX_CONTOUR_VERTICES."},
        415: {"description": "The body is not application/geo+json or application/json."},
        429: {
            "description": "Too many builds run and wait (CCSM_MAX_BUILDS, CCSM_BUILD_QUEUE), or too many uploads "
            "are being checked (CCSM_UPLOAD_CHECKS, CCSM_UPLOAD_CHECK_QUEUE); see Retry-After."
        },
        503: {"description": "The upload's check passed CCSM_UPLOAD_CHECK_TIMEOUT_S or its process died."},
        507: {"description": "The store or the upload folder cannot be written (full disk, read-only)."},
    },
)
async def upload_dataset(
    request: Request,
    service: Annotated[DatasetService, Depends(get_service)],
    settings: Annotated[Settings, Depends(get_settings)],
    id: Annotated[
        str | None,
        Query(
            description="Dataset id to create (a-z, 0-9, _ and -); default from name.",
            max_length=64,
            pattern=r"^[a-z0-9_-]+$",
        ),
    ] = None,
    name: Annotated[str | None, Query(description="Human name of the dataset.", max_length=200)] = None,
    elevation_field: Annotated[
        str | None, Query(description="Elevation property (found by name if unset).", max_length=100)
    ] = None,
    interval: Annotated[
        float | None, Query(description="Contour interval (inferred if unset).", gt=0, allow_inf_nan=False)
    ] = None,
    source_scale: Annotated[
        float | None,
        Query(description="Scale denominator of the contours (t = 0).", gt=0, le=1e9, allow_inf_nan=False),
    ] = None,
    target_scale: Annotated[
        float | None, Query(description="Scale denominator of t = 1.", gt=0, le=1e10, allow_inf_nan=False)
    ] = None,
    units: Annotated[
        Literal["m", "ft", "fm"] | None,
        Query(description="Vertical unit (default: as the elevation property's name states it, else m)."),
    ] = None,
    index_every: Annotated[int, Query(description="Index contours are every n-th interval.", ge=2, le=100)] = 5,
    attribute_names: Annotated[
        Literal["ccsm", "maplibre-contour"], Query(description="Tile attribute names (maplibre-contour: `ele`).")
    ] = "ccsm",
    schedule: Annotated[
        str | None,
        Query(description="Interval schedule override STEP:HIDE_SCALE,...,STEP (docs/design.md section 9).",
              max_length=500),
    ] = None,
    attribution: Annotated[
        str | None, Query(description="Who made the data, for TileJSON.", max_length=500)
    ] = None,
    sea: Annotated[
        Literal["drop", "coastline", "keep"],
        Query(description="The 0 m line: dropped, drawn as a coastline, or an ordinary contour."),
    ] = "drop",
    depth_labels: Annotated[
        Literal["negative", "below-datum"], Query(description="Negative levels labelled -200 m or 200 m.")
    ] = "negative",
    label_orientation: Annotated[
        Literal["uphill", "upright"], Query(description="Label text top toward higher ground, or upright.")
    ] = "uphill",
) -> JSONResponse:
    """Upload GeoJSON contours (the document itself is the body); answered 202 while the dataset builds in
    a build process of its own."""
    params = UploadParams(
        elevation_field=elevation_field,
        interval=interval,
        source_scale=source_scale or settings.source_scale,
        target_scale=target_scale or settings.target_scale,
        cartography=CartographyOptions(
            units, index_every, attribute_names, schedule, attribution, sea, depth_labels, label_orientation
        ),
    )
    params.check()  # bad scales or options are refused before the body is read
    # The body goes to a file as it arrives, and is parsed in a process of its own: never on the event loop
    # (docs/service.md, "Uploads").
    incoming = await receive_upload(request, service.upload_dir, settings.max_upload_bytes)
    try:
        job = UploadCheck(
            incoming, elevation_field, interval, params.as_dict(), params.cartography, params.source_scale,
            max_contour_vertices=settings.max_contour_vertices or None,
        )
        checked = await unless_client_goes(request, get_upload_checker(request).check(job))
    except BaseException:
        incoming.unlink(missing_ok=True)
        raise
    out: dict[str, Any] = await run_in_threadpool(
        service.accept_upload, incoming, checked, dataset=id, name=name, params=params
    )
    return JSONResponse(out, status_code=202, headers={"Location": out["href"], **NO_STORE})


@router.delete(
    "/datasets/{dataset}",
    status_code=204,
    dependencies=[Depends(require_writer)],
    responses={
        401: {"description": "CCSM_ADMIN_TOKEN is set and the bearer token is missing or wrong."},
        403: {"description": "No token is set and the client is not local."},
        404: {"description": "Unknown dataset."},
    },
)
def delete_dataset(
    dataset: DatasetPath, service: Annotated[DatasetService, Depends(get_service)]
) -> Response:
    """Delete a dataset, ready, building (its build stops) or failed; a configured source is rebuilt at the
    next start."""
    service.delete(dataset)
    return Response(status_code=204)
