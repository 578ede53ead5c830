"""Health check, the landing page and the web map's static files."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Request
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse, Response

from app.dependencies import get_service, get_settings
from app.service import DatasetService
from app.settings import Settings

router = APIRouter(tags=["meta"])


@router.get("/healthz")
def healthz(service: Annotated[DatasetService, Depends(get_service)]) -> JSONResponse:
    """Liveness and readiness: 200 while the process can read its store."""
    states: dict[str, int] = {}
    for item in service.summaries():
        states[item["state"]] = states.get(item["state"], 0) + 1
    return JSONResponse({"status": "ok", "datasets": states}, headers={"Cache-Control": "no-store"})


@router.get(
    "/readyz",
    responses={503: {"description": "Not ready: the reasons are listed (store, disk, datasets)."}},
)
def readyz(request: Request) -> JSONResponse:
    """Readiness: 200 when the store can be written and every dataset is ready; else 503 with the reasons
    (a damaged or unwritable store, a nearly full disk, datasets building or failed)."""
    service: DatasetService | None = request.app.state.service
    problems = [request.app.state.store_problem] if service is None else service.readiness()
    status = 503 if problems else 200
    body = {"status": "not ready" if problems else "ready", "problems": problems}
    return JSONResponse(body, status_code=status, headers={"Cache-Control": "no-store"})


@router.get("/", include_in_schema=False)
def index(request: Request, settings: Annotated[Settings, Depends(get_settings)]) -> Response:
    """The web map (web/index.html) when it exists, else a short page of links."""
    page = settings.web_dir / "index.html"
    if page.is_file():
        return FileResponse(page, media_type="text/html", headers={"Cache-Control": "no-cache"})
    return HTMLResponse(
        "<!doctype html><title>ccsm</title><h1>ccsm</h1><ul>"
        '<li><a href="/docs">API documentation</a></li><li><a href="/datasets">datasets</a></li>'
        '<li><a href="/healthz">health</a></li></ul>'
    )
