"""Health check, the landing page and the web map's static files."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Request
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse, Response

from app.routes.dependencies import get_settings
from app.service import DatasetService
from app.settings import Settings

router = APIRouter(tags=["meta"])


@router.get("/healthz")
async def healthz() -> JSONResponse:
    """Liveness only: 200 while the event loop runs. It reads nothing (no store, no lock, no thread), so it
    answers at once under any load; whether datasets are ready is the readiness endpoint's question."""
    return JSONResponse({"status": "ok"}, headers={"Cache-Control": "no-store"})


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
